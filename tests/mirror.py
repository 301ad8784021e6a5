"""The left-right mirror of a scene (x -> -x), for the mirror-symmetry tests of the forward model."""

from __future__ import annotations

import dataclasses

from eyehil.emulator.optics.camera import PinholeCamera
from eyehil.emulator.scene import Scene


def mirror_scene(scene: Scene) -> Scene:
    """`scene` mirrored about the head's sagittal plane: camera, LEDs and head positions, and the sides swapped."""
    cam = scene.camera
    pose = cam.pose_deg
    mirrored_cam = PinholeCamera.from_angles(
        position=cam.position * [-1, 1, 1], pitch_deg=pose["pitch_deg"], yaw_deg=-pose["yaw_deg"],
        roll_deg=-pose["roll_deg"], focal_px=cam.focal_px, principal_px=cam.principal_px,
        resolution_px=cam.resolution_px)
    heads = tuple(dataclasses.replace(h, x=-h.x, yaw=-h.yaw, roll=-h.roll) for h in scene.head_positions)
    return dataclasses.replace(scene, camera=mirrored_cam, leds=scene.leds * [-1, 1, 1], head_positions=heads,
                               sides=tuple({"right": "left", "left": "right"}[s] for s in scene.sides))
