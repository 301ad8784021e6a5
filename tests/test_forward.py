"""The forward model end to end: convergence on the published eyes, geometry, symmetry, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mirror import mirror_scene

from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import Poses, simulate
from eyehil.emulator.optics.camera import PinholeCamera
from eyehil.emulator.scene import Screen, load_scene


@pytest.fixture(scope="module")
def published():
    return published_eyes()


@pytest.mark.parametrize("preset", ["guestrin2006", "blignaut2014"])
def test_every_fixation_and_glint_of_the_published_eyes_converges(published, preset: str) -> None:
    f = simulate(published, load_scene(preset))
    assert f.shape[0] == 100
    assert f.valid.all(), f.counts()
    assert np.max(f.fixation_residual_mm) <= 0.01
    assert np.max(f.glint_residual_mm) <= 1e-4
    assert np.max(f.pupil_residual_mm) <= 1e-6
    assert f.pupil_points_valid.all()


def test_line_of_sight_passes_through_each_target(eyes) -> None:
    scene = load_scene("guestrin2006")
    f = simulate(eyes, scene)
    to_target = scene.targets()[None, None, None] - f.los_origin  # scene frame, every head position
    along = np.einsum("...k,...k->...", to_target, f.visual_axis)
    miss = np.linalg.norm(to_target - along[..., None] * f.visual_axis, axis=-1)
    assert np.all(along > 500) and miss.max() < 1e-6  # mm


def test_ground_truth_geometry_is_consistent(eyes) -> None:
    f = simulate(eyes, load_scene("blignaut2014"))
    r = np.broadcast_to(eyes.anterior_radius[:, None, None, None], f.shape)
    np.testing.assert_allclose(np.linalg.norm(f.apex - f.cornea_centre, axis=-1), r, atol=1e-9)
    np.testing.assert_allclose((f.apex - f.cornea_centre) / r[..., None], f.optic_axis, atol=1e-9)
    k = np.linalg.norm(f.pupil_centre - f.cornea_centre, axis=-1)
    expected_k = np.broadcast_to((eyes.anterior_radius - eyes.stop_depth)[:, None, None, None], f.shape)
    np.testing.assert_allclose(k, expected_k, atol=1e-9)
    # pupil moves right in the image when the eye turns toward +x (azimuth > 0)
    sides = f.azimuth_deg[0, 0, 0]
    px = f.pupil_centre_px[0, 0, 0, :, 0]
    order = np.argsort(sides)
    assert np.corrcoef(sides[order], px[order])[0, 1] > 0.99


def test_explicit_poses_primary_position_and_listing(eyes) -> None:
    scene = load_scene("guestrin2006")
    f = simulate(eyes, scene, poses=Poses(np.array([0.0, 20.0, 0.0]), np.array([0.0, 0.0, 15.0])),
                 head_positions=scene.head_positions[:1])
    np.testing.assert_allclose(f.optic_axis[:, 0, 0, 0], np.tile([0.0, 0.0, 1.0], (len(eyes), 1)), atol=1e-12)
    np.testing.assert_allclose(f.torsion_deg[..., :3], 0.0, atol=1e-12)  # no pseudo-torsion on the cardinal axes
    central = scene.head_positions[:1]
    oblique = simulate(eyes, scene, poses=Poses(np.array([20.0]), np.array([15.0])), head_positions=central)
    assert np.all(np.abs(oblique.torsion_deg) > 1.0)
    free = simulate(eyes, scene, poses=Poses(np.array([20.0]), np.array([15.0]), np.array([0.0])),
                    head_positions=scene.head_positions[:1])
    assert np.all(free.torsion_deg == 0.0)


def test_left_right_mirror_symmetry(eyes) -> None:
    base = load_scene("guestrin2006")
    scene = dataclasses.replace(base, camera=PinholeCamera.from_angles(
        position=np.array([25.0, -150.5, 615.0]), pitch_deg=13.75, yaw_deg=4.0, roll_deg=2.0,
        focal_px=(4666.67, 4666.67), principal_px=(320.0, 240.0), resolution_px=(640, 480)),
        leds=np.array([[150.0, 20.0, 640.0], [-220.0, 0.0, 660.0]]))
    targets = scene.targets() + np.array([30.0, 10.0, 0.0])
    right = simulate(eyes, scene, targets=targets)
    left = simulate(eyes, mirror_scene(scene), targets=targets * [-1, 1, 1])
    cx = scene.camera.principal_px[0]
    np.testing.assert_allclose(2 * cx - left.pupil_centre_px[..., 0], right.pupil_centre_px[..., 0], atol=1e-6)
    np.testing.assert_allclose(left.pupil_centre_px[..., 1], right.pupil_centre_px[..., 1], atol=1e-6)
    np.testing.assert_allclose(2 * cx - left.glint_px[..., 0], right.glint_px[..., 0], atol=1e-6)
    np.testing.assert_allclose(left.glint_px[..., 1], right.glint_px[..., 1], atol=1e-6)
    np.testing.assert_allclose(-left.azimuth_deg, right.azimuth_deg, atol=1e-8)
    np.testing.assert_allclose(left.elevation_deg, right.elevation_deg, atol=1e-8)


def test_target_behind_the_eye_is_refused(eyes) -> None:
    with pytest.raises(ValueError, match="in front"):
        simulate(eyes, load_scene("guestrin2006"), targets=np.array([[0.0, 0.0, -100.0]]))
    with pytest.raises(ValueError, match="finite"):
        simulate(eyes, load_scene("guestrin2006"), targets=np.array([[0.0, np.nan, 600.0]]))


def test_glints_off_the_cornea_are_flagged_invalid_never_a_silent_nan(eyes) -> None:
    """An LED far to the side: its reflection leaves the cornea for some gaze directions."""
    scene = load_scene("guestrin2006").with_leds(np.array([[188.5, 0.0, 650.0], [-2000.0, 0.0, 1.0]]))
    f = simulate(eyes, scene)
    side = f.glint_valid[..., 1]
    assert f.glint_valid[..., 0].all() and side.any() and not side.all()
    np.testing.assert_array_equal(np.isnan(f.glint_px[..., 1, 0]), ~side)  # NaN exactly where flagged
    np.testing.assert_array_equal(f.valid, side)
    assert f.counts()["glints_invalid"] == np.count_nonzero(~side)


def test_led_behind_the_eyes_is_refused() -> None:
    with pytest.raises(ValueError, match="LED"):
        load_scene("guestrin2006").with_leds(np.array([[0.0, 0.0, -50.0]]))


def test_features_save_round_trip(tmp_path, eyes) -> None:
    f = simulate(eyes[:1], load_scene("blignaut2014"))
    path = f.save(tmp_path / "features.npz")
    data = np.load(path)
    np.testing.assert_array_equal(data["pupil_centre_px"], f.pupil_centre_px)
    assert "guestrin" not in str(data["meta"]) and "blignaut2014" in str(data["meta"])


def test_screen_targets_are_numbered_column_by_column_from_the_plus_x_edge() -> None:
    screen = Screen(centre=np.array([0.0, -140.0, 800.0]), size=(495.0, 280.0), grid=(15, 9))
    t = screen.targets()
    assert t.shape == (135, 3)
    np.testing.assert_allclose(t[0], [247.5, 0.0, 800.0])  # column 0 at +x, row 0 at the top
    np.testing.assert_allclose(t[8], [247.5, -280.0, 800.0])
    np.testing.assert_allclose(t[134], [-247.5, -280.0, 800.0])
    np.testing.assert_allclose(t[67], [0.0, -140.0, 800.0], atol=1e-9)  # index 68 (1-based) is the centre
