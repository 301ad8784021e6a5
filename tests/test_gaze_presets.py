"""The preset scenes' camera pitch: each camera is aimed at the eyes' height from its position."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eyehil.emulator.scene import load_scene


@pytest.mark.parametrize("preset", ["guestrin2006", "guestrin2006-table3", "blignaut2014"])
def test_camera_pitch_aims_at_the_eyes(preset: str) -> None:
    scene = load_scene(preset)
    _, y, z = scene.camera.position
    derived = math.degrees(math.atan2(-y, z))  # below the eyes, ahead: tilted up by atan(depth below / distance)
    assert scene.camera.pose_deg["pitch_deg"] == pytest.approx(derived, abs=5e-7)
    # the optical axis then passes through the eyes' height at z = 0 (within 1e-5 mm)
    axis = scene.camera.rotation[2]
    t = -z / axis[2]
    np.testing.assert_allclose(y + t * axis[1], 0.0, atol=1e-5)


def test_known_pitches() -> None:
    assert math.degrees(math.atan(150.5 / 615)) == pytest.approx(13.750919, abs=5e-7)
    assert math.degrees(math.atan(300 / 520)) == pytest.approx(29.981639, abs=5e-7)
