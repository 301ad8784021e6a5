"""The host's tracker geometry file (TOML): camera, LEDs and screen in the WORLD frame of `eyehil.drivers.gaze.geometry`.

A real tracker ships this as its setup file; the emulator writes one for its scene with
``eyehil emulate --write-geometry FILE``. Format, version 1 (mm, px; every key required unless noted)::

    format = "eyehil-geometry"
    version = 1
    scene = "guestrin2006"                  # optional, informative
    [camera]
    matrix_px = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]      # intrinsics K, OpenCV pixel convention
    rotation = [[...], [...], [...]]        # R, world -> camera (camera axes: x right, y down in the image)
    position_mm = [x, y, z]                 # nodal point o: X_camera = R (X_world - o)
    resolution_px = [width, height]
    [[leds]]                                # one table per LED, in LED id order (id 0 first)
    position_mm = [x, y, z]
    [screen]
    centre_mm = [x, y, z]
    size_mm = [width, height]               # active area
    x_axis = [1, 0, 0]                      # optional: the screen's unit axes in the world (default world +x, +y)
    y_axis = [0, 1, 0]

World frame: mm, x to the subject's left, y up, z toward the screen; the subject's eyes near z = 0.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eyehil.drivers.gaze.geometry import Camera, Screen, TrackerGeometry

FORMAT = "eyehil-geometry"
VERSION = 1


@dataclass(frozen=True)
class SetupFile:
    """A loaded geometry file: the geometry and where it came from."""

    geometry: TrackerGeometry
    scene: str
    path: Path


def _array(table: dict, key: str, where: str, shape: tuple[int, ...]) -> np.ndarray:
    """`table[key]` as a float array of `shape`; ValueError naming the key otherwise."""
    if key not in table:
        raise ValueError(f"{where}.{key}: missing")
    try:
        value = np.array(table[key], dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}.{key}: not numbers: {table[key]!r}") from exc
    if value.shape != shape or not np.all(np.isfinite(value)):
        raise ValueError(f"{where}.{key}: expected {shape} finite numbers, got {table[key]!r}")
    return value


def geometry_from_dict(data: dict) -> TrackerGeometry:
    """Build and validate a `TrackerGeometry` from the parsed TOML."""
    if data.get("format") != FORMAT or data.get("version") != VERSION:
        raise ValueError(f"not an {FORMAT} version {VERSION} file (format={data.get('format')!r}, "
                         f"version={data.get('version')!r})")
    cam, screen, leds = data.get("camera", {}), data.get("screen", {}), data.get("leds", [])
    width, height = _array(cam, "resolution_px", "camera", (2,))
    camera = Camera(K=_array(cam, "matrix_px", "camera", (3, 3)), R=_array(cam, "rotation", "camera", (3, 3)),
                    o=_array(cam, "position_mm", "camera", (3,)), image_size=(int(width), int(height)))
    if not isinstance(leds, list) or not leds:
        raise ValueError("leds: expected one or more [[leds]] tables")
    led_positions = np.stack([_array(led, "position_mm", f"leds[{i}]", (3,)) for i, led in enumerate(leds)])
    axes = {k: _array(screen, k, "screen", (3,)) for k in ("x_axis", "y_axis") if k in screen}
    size = _array(screen, "size_mm", "screen", (2,))
    scr = Screen(centre=_array(screen, "centre_mm", "screen", (3,)), size_mm=(size[0], size[1]), **axes)
    return TrackerGeometry(camera=camera, leds=led_positions, screen=scr)


def load_geometry(path: str | Path) -> SetupFile:
    """Read a geometry file; ValueError (naming the key) if it is malformed."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from exc
    try:
        return SetupFile(geometry_from_dict(data), str(data.get("scene", "")), path)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc
