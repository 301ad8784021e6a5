"""The tracker's camera as it really is, which the host's pinhole model does not know.

## Tangential (decentring) distortion (`TangentialDistortion`)

Frame: normalised camera coordinates (x, y) = ((u - cx) / fx, (v - cy) / fy) of the image pixels
(OpenCV convention). Brown's decentring terms, as OpenCV's p1, p2:

    x' = x + 2 p1 x y + p2 (r^2 + 2 x^2),   y' = y + p1 (r^2 + 2 y^2) + 2 p2 x y,   r^2 = x^2 + y^2,

applied to the pupil-ellipse centre and every glint centre of every fixation (a feature-stage effect: the
map is smooth at the scale of a pupil, so the distorted ellipse's centre is the distorted centre to
first order). Radial distortion is `lens_distortion` (eyehil.emulator.effects.scene), which acts in the ray
tracing. Scale: the Guestrin 2006 camera sees |x| <= 0.07; a displacement 2 p r^2 f is 0.05 px at r = 0.05
for p = 1e-3 (f = 4667 px); what matters is its change across the pupil-glint vector.
Reference: Brown 1966 (Photogramm. Eng. 32(3):444-462); Zhang 2000 (IEEE TPAMI 22(11):1330-1334).

## Camera pose error (`CameraPose`) and a bumped camera (`CameraBump`)

The camera's true orientation differs from the host's belief by `pitch_deg` (about world x; + tilts the
view up) and `yaw_deg` (about world y; + turns the view toward +x), the named angles of
`eyehil.emulator.optics.camera` (the rotation is about the camera's nodal point). `CameraPose`: in every session
(a set-up measured wrong: the calibration absorbs most of it). `CameraBump`: only at the validation
head positions (the camera knocked after calibration; nothing absorbs it).
Reference: Guestrin & Eizenman 2006 (IEEE TBME 53(6):1124-1133, the geometry the host assumes known);
Hartley & Zisserman 2004 (Multiple View Geometry, ch. 6).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter, with_arrays
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.optics.camera import orientation
from eyehil.emulator.scene import Scene


def tangential(points_px: np.ndarray, focal_px, principal_px, p1: float, p2: float) -> np.ndarray:
    """Pixels (..., 2) moved by Brown's decentring distortion (p1, p2) about the principal point."""
    f, c = np.asarray(focal_px, float), np.asarray(principal_px, float)
    x, y = ((points_px - c) / f)[..., 0], ((points_px - c) / f)[..., 1]
    r2 = x * x + y * y
    xd = x + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1) * f + c


class TangentialDistortion(Effect):
    """Uncorrected decentring (tangential) lens distortion p1, p2 (normalised coordinates)."""

    name = "tangential_distortion"
    stage = "features"
    reference = "Brown 1966, Photogramm. Eng. 32(3):444-462; Zhang 2000, IEEE TPAMI 22(11):1330-1334"
    prior = "|p1|, |p2| of order 1e-4-1e-3 for machine-vision lenses"
    parameters = (
        Parameter("p1", "", 0.0, -0.05, 0.05, doc="OpenCV p1"),
        Parameter("p2", "", 0.0, -0.05, 0.05, doc="OpenCV p2"),
    )

    def perturb(self, features: Features, values: Mapping[str, float], rng: np.random.Generator | None,
                **kwargs: object) -> Features:
        from eyehil.emulator.scene import load_scene

        camera = load_scene(features.scene).camera
        p1, p2 = float(values["p1"]), float(values["p2"])
        move = lambda u: tangential(u, camera.focal_px, camera.principal_px, p1, p2)  # noqa: E731
        return with_arrays(features, pupil_centre_px=move(features.pupil_centre_px), glint_px=move(features.glint_px))


def _turned(scene: Scene, pitch: float, yaw: float) -> Scene:
    camera = scene.camera
    if not camera.pose_deg:
        raise ValueError("the scene's camera was not built from named angles")
    pose = {**camera.pose_deg, "pitch_deg": camera.pose_deg["pitch_deg"] + pitch,
            "yaw_deg": camera.pose_deg["yaw_deg"] + yaw}
    rotation = orientation(pose["pitch_deg"], pose["yaw_deg"], pose["roll_deg"])
    return replace(scene, camera=replace(camera, rotation=rotation, pose_deg=pose))


class CameraPose(Effect):
    """The camera's true orientation off the host's belief (deg pitch, deg yaw), in every session."""

    name = "camera_pose"
    reference = "Guestrin & Eizenman 2006, IEEE TBME 53(6):1124-1133; Hartley & Zisserman 2004, ch. 6"
    prior = "0 +- 0.5 deg for a set-up measured with a ruler"
    parameters = (
        Parameter("pitch_deg", "deg", 0.0, -3.0, 3.0, doc="added to the camera pitch (+ view up)"),
        Parameter("yaw_deg", "deg", 0.0, -3.0, 3.0, doc="added to the camera yaw (+ view toward +x)"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        return eyes, _turned(scene, float(values["pitch_deg"]), float(values["yaw_deg"]))


class CameraBump(Effect):
    """The camera turned after calibration (deg pitch, deg yaw), at the validation head positions."""

    name = "camera_bump"
    reference = "Guestrin & Eizenman 2006, IEEE TBME 53(6):1124-1133"
    prior = "0; a knocked camera turns by tenths of a degree"
    validation_only = True
    parameters = (
        Parameter("pitch_deg", "deg", 0.0, -0.5, 0.5, doc="added to the camera pitch at validation"),
        Parameter("yaw_deg", "deg", 0.0, -0.5, 0.5, doc="added to the camera yaw at validation"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        if session != "validation":
            return eyes, scene
        return eyes, _turned(scene, float(values["pitch_deg"]), float(values["yaw_deg"]))
