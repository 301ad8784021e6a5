"""Where analysis joins the emulator and the host: what a host would know about a scene, and the
features the emulator computed, in the host's terms.

The host's world frame is the scene frame (mm; x to the subject's left, y up, z toward the screen);
screen coordinates are mm from the screen centre along world +x and +y (`eyehil.drivers.gaze.geometry`).
"""

from __future__ import annotations

import numpy as np

from eyehil.drivers.gaze.base import BinocularSamples, EyeSamples
from eyehil.drivers.gaze.geometry import Camera, Screen, TrackerGeometry
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene


def tracker_geometry(scene: Scene) -> TrackerGeometry:
    """The calibrated tracker geometry a host has for `scene` (camera without lens distortion)."""
    cam = scene.camera
    if any(cam.distortion):
        raise ValueError("the host estimators assume an undistorted camera; undistort features first")
    camera = Camera(K=cam.matrix, R=cam.rotation, o=cam.position, image_size=cam.resolution_px)
    screen = Screen(centre=scene.screen.centre, size_mm=scene.screen.size)
    return TrackerGeometry(camera=camera, leds=scene.leds, screen=screen)


def eye_samples(features: Features, side: str, *, visible_only: bool = False) -> EyeSamples:
    """(E, H, T) samples of one side: pupil ellipse centre and glints, px; `visible_only` drops off-sensor ones."""
    s = features.sides.index(side)
    valid = (features.visible if visible_only else features.valid)[:, s]
    pupil = np.where(valid[..., None], features.pupil_centre_px[:, s], np.nan)
    glints = np.where(valid[..., None, None], features.glint_px[:, s], np.nan)
    return EyeSamples(pupil, glints, valid)


def binocular_samples(features: Features, *, visible_only: bool = False) -> BinocularSamples:
    """(E, H, T) samples of both eyes."""
    return BinocularSamples(eye_samples(features, "right", visible_only=visible_only),
                            eye_samples(features, "left", visible_only=visible_only))


def screen_targets(scene: Scene, targets: np.ndarray | None = None) -> np.ndarray:
    """Targets (T, 2) in screen mm."""
    return scene.screen.to_screen(scene.targets() if targets is None else targets)
