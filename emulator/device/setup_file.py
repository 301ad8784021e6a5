"""Write the host's tracker geometry file (TOML) for a scene: what a real tracker's setup file would hold.

A host calibrating gaze needs its tracker's geometry (camera intrinsics and pose, LED positions,
screen). A product ships it as a setup file; `eyehil emulate --write-geometry FILE` writes one for the
emulated scene, and `eyehil.drivers.setup_file.load_geometry` reads it (the format is specified there, and
the host never imports the emulator). Frame: the scene frame (mm; x to the subject's left, y up, z
toward the screen), which is the host's WORLD frame (`eyehil.drivers.gaze.geometry`). Only the tracker and the
screen are written: the subject's head pose and eyes are not the host's to know.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from eyehil.emulator.scene import Scene

FORMAT = "eyehil-geometry"
VERSION = 1


def _num(value: float) -> str:
    """A TOML float with full precision."""
    return repr(float(value))


def _vector(values: Iterable[float]) -> str:
    return "[" + ", ".join(_num(v) for v in values) + "]"


def _matrix(rows: np.ndarray) -> str:
    return "[" + ", ".join(_vector(row) for row in np.asarray(rows, float)) + "]"


def geometry_toml(scene: Scene) -> str:
    """The geometry file's text for `scene` (refuses a distorted camera: the host models a pinhole)."""
    cam = scene.camera
    if any(cam.distortion):
        raise ValueError(f"scene {scene.name}: the host geometry file describes an undistorted pinhole camera")
    lines = [
        f"# Tracker geometry for the emulated scene {scene.name!r}, written by `eyehil emulate --write-geometry`.",
        "# World frame: mm, x to the subject's left, y up, z toward the screen (eyehil.drivers.setup_file).",
        f'format = "{FORMAT}"', f"version = {VERSION}", f'scene = "{scene.name}"', "",
        "[camera]",
        f"matrix_px = {_matrix(cam.matrix)}  # intrinsics K",
        f"rotation = {_matrix(cam.rotation)}  # world -> camera (OpenCV axes)",
        f"position_mm = {_vector(cam.position)}  # nodal point",
        f"resolution_px = [{int(cam.resolution_px[0])}, {int(cam.resolution_px[1])}]", "",
    ]
    for led in scene.leds:
        lines += ["[[leds]]", f"position_mm = {_vector(led)}", ""]
    lines += ["[screen]", f"centre_mm = {_vector(scene.screen.centre)}", f"size_mm = {_vector(scene.screen.size)}",
              "x_axis = [1.0, 0.0, 0.0]  # screen x: world +x (the subject's left)", "y_axis = [0.0, 1.0, 0.0]", ""]
    return "\n".join(lines)


def write_geometry(scene: Scene, path: str | Path) -> Path:
    """Write `geometry_toml(scene)` to `path`; return the path."""
    path = Path(path)
    path.write_text(geometry_toml(scene), encoding="utf-8")
    return path
