"""Host geometry, the estimator interface and Guestrin & Eizenman 2006 against an independent spherical eye."""

from __future__ import annotations

import numpy as np
import pytest
from spherical_eye import RIGHT_APEX, SphericalEye, guestrin_geometry, simulate

from eyehil.drivers.gaze.base import CalibrationFailure, EyeSamples, angular_error_deg, on_screen_error_deg
from eyehil.drivers.gaze.geometry import Camera, Screen, TrackerGeometry
from eyehil.drivers.gaze.guestrin import EyeParameters, GuestrinEstimator, point_of_gaze, reconstruct, visual_axis

HEAD_OFFSETS = {"central": (0, 0, 0), "left": (30, 0, 0), "right": (-30, 0, 0), "forward": (0, 0, 40),
                "back": (0, 0, -40), "oblique": (12, 15, -25)}
MOVED = ("left", "right", "forward", "back")
EYE = SphericalEye(R=7.4, K=4.6, alpha_deg=5.6, beta_deg=2.2)


@pytest.fixture(scope="module")
def geometry() -> TrackerGeometry:
    return guestrin_geometry()


@pytest.fixture(scope="module")
def targets(geometry) -> np.ndarray:
    return geometry.screen.grid(3, 3).reshape(-1, 2)


def truth(eye: SphericalEye) -> EyeParameters:
    return EyeParameters(eye.R, eye.K, eye.alpha_deg, eye.beta_deg, eye.n1)


def gaze_error_deg(geometry, fix, estimate_mm) -> np.ndarray:
    return angular_error_deg(fix.c, geometry.screen.to_world(estimate_mm), fix.targets_world)


# --- geometry and helpers -------------------------------------------------------------------------------------


def test_camera_looks_at_origin_and_round_trips(geometry):
    cam = geometry.camera
    np.testing.assert_allclose(cam.project(np.zeros(3)), [320.0, 240.0], atol=1e-9)
    np.testing.assert_allclose(cam.R[0], [1.0, 0.0, 0.0], atol=1e-15)  # image x = world +x
    axis = np.array([0.0, 150.5, -615.0]) / np.hypot(150.5, 615.0)
    np.testing.assert_allclose(cam.R[2], axis, atol=1e-15)
    assert cam.project(np.array([0.0, 10.0, 0.0]))[1] < 240.0  # up in the world is up in the image
    pts = np.random.default_rng(1).uniform([-60, -40, -30], [60, 40, 30], (50, 3))
    px = cam.project(pts)
    rays = cam.ray_directions(px)
    along = np.cross(rays, pts - cam.o)
    np.testing.assert_allclose(along, 0.0, atol=1e-9)


def test_geometry_validation():
    K = np.array([[100.0, 0, 10], [0, 100, 10], [0, 0, 1]])
    with pytest.raises(ValueError):
        Camera(K=K, R=np.diag([1.0, 1.0, 2.0]), o=np.zeros(3), image_size=(20, 20))
    with pytest.raises(ValueError):
        Camera(K=K, R=np.diag([1.0, 1.0, -1.0]), o=np.zeros(3), image_size=(20, 20))
    with pytest.raises(ValueError):
        Screen(centre=(0, 0, 1), size_mm=(1, 1), x_axis=(1, 0, 0), y_axis=(1, 0, 0))
    with pytest.raises(ValueError):
        TrackerGeometry(Camera(K, np.eye(3), np.zeros(3), (20, 20)), leds=np.zeros(3), screen=Screen((0, 0, 1), (1, 1)))


def test_screen_round_trip(geometry):
    screen = geometry.screen
    xy = np.array([[10.0, -20.0], [-100.0, 50.0]])
    np.testing.assert_allclose(screen.to_screen(screen.to_world(xy)), xy, atol=1e-12)
    origin = np.array([-31.5, 0.0, 0.0])
    direction = screen.to_world(xy) - origin
    np.testing.assert_allclose(screen.intersect(origin, direction), xy, atol=1e-9)
    assert np.all(np.isnan(screen.intersect(origin, -direction)))  # behind the origin
    assert screen.to_world(np.array([10.0, 0.0]))[0] == 10.0  # screen x = world x (subject's left)


def test_error_forms_known_answer():
    est, tgt = np.array([10.0, 0.0]), np.zeros(2)
    assert on_screen_error_deg(est, tgt) == pytest.approx(np.degrees(np.arctan(10.0 / 650.0)), abs=1e-12)
    eye = np.zeros(3)
    world = angular_error_deg(eye, np.array([10.0, 0.0, 650.0]), np.array([0.0, 0.0, 650.0]))
    assert world == pytest.approx(np.degrees(np.arctan(10.0 / 650.0)), abs=1e-12)


def test_visual_axis_angle_addition_sign():
    nu = visual_axis(np.array([0.0, 0.0, 1.0]), 5.0, 1.5)
    np.testing.assert_allclose(nu, [np.cos(np.radians(1.5)) * np.sin(np.radians(5.0)), np.sin(np.radians(1.5)),
                                    np.cos(np.radians(1.5)) * np.cos(np.radians(5.0))], atol=1e-15)


# --- model-based estimation -----------------------------------------------------------------------------------


@pytest.mark.parametrize("head", list(HEAD_OFFSETS))
def test_exact_model_gives_exact_gaze(geometry, targets, head):
    fix = simulate(EYE, geometry, RIGHT_APEX + np.array(HEAD_OFFSETS[head], float), targets)
    c, _ = reconstruct(geometry, fix.samples, truth(EYE))
    np.testing.assert_allclose(c, fix.c, atol=1e-6)
    error = gaze_error_deg(geometry, fix, point_of_gaze(geometry, fix.samples, truth(EYE)))
    assert error.max() < 0.01
    assert error.max() < 1e-6  # measured about 1e-10 deg


def test_left_eye_exact(geometry, targets):
    eye = SphericalEye(R=7.6, K=4.4, alpha_deg=-5.2, beta_deg=1.8)
    fix = simulate(eye, geometry, -RIGHT_APEX, targets)
    assert gaze_error_deg(geometry, fix, point_of_gaze(geometry, fix.samples, truth(eye))).max() < 1e-6


@pytest.mark.parametrize("objective", ["screen", "angular"])
def test_calibration_round_trip(geometry, targets, objective):
    central = simulate(EYE, geometry, RIGHT_APEX, targets)
    cal = GuestrinEstimator(geometry, eye="right", objective=objective).calibrate(central.samples, targets)
    assert cal
    fitted = cal.parameters
    np.testing.assert_allclose([fitted.R, fitted.K, fitted.alpha_deg, fitted.beta_deg],
                               [EYE.R, EYE.K, EYE.alpha_deg, EYE.beta_deg], atol=1e-6)
    assert cal.params["n1"] == 1.3375 and cal.params["objective"] == objective
    for head in MOVED:
        fix = simulate(EYE, geometry, RIGHT_APEX + np.array(HEAD_OFFSETS[head], float), targets)
        assert gaze_error_deg(geometry, fix, cal.estimate(fix.samples)).max() < 0.01


def test_corneal_index_fitted_or_fixed(geometry, targets):
    eye = SphericalEye(R=7.9, K=4.0, alpha_deg=4.5, beta_deg=1.0, n1=1.376)
    fix = simulate(eye, geometry, RIGHT_APEX, targets)
    cal = GuestrinEstimator(geometry, fit_n1=True).calibrate(fix.samples, targets)
    assert cal.params["n1"] == pytest.approx(1.376, abs=1e-6) and "n1" in cal.fitted
    fixed = GuestrinEstimator(geometry, n1=1.376).calibrate(fix.samples, targets)
    assert abs(fixed.parameters.R - 7.9) < 1e-6
    mismatched = GuestrinEstimator(geometry).calibrate(fix.samples, targets)  # public code's 1.3375
    assert mismatched.params["n1"] == 1.3375 and mismatched.cost > 1e-6


def test_one_led_with_known_distance(geometry, targets):
    one = TrackerGeometry(geometry.camera, geometry.leds[:1], geometry.screen)
    central = simulate(EYE, one, RIGHT_APEX, targets)
    distance = np.linalg.norm(central.c - one.camera.o, axis=-1)
    exact = point_of_gaze(one, central.samples, truth(EYE), eye_distance_mm=distance)
    assert gaze_error_deg(one, central, exact).max() < 1e-6
    cal = GuestrinEstimator(one, eye_distance_mm=distance).calibrate(central.samples, targets)
    np.testing.assert_allclose([cal.parameters.R, cal.parameters.K], [EYE.R, EYE.K], atol=1e-6)
    for head in MOVED:
        fix = simulate(EYE, one, RIGHT_APEX + np.array(HEAD_OFFSETS[head], float), targets)
        moved = cal.with_eye_distance(np.linalg.norm(fix.c - one.camera.o, axis=-1))
        assert gaze_error_deg(one, fix, moved.estimate(fix.samples)).max() < 0.01
    with pytest.raises(ValueError, match="eye_distance_mm"):
        GuestrinEstimator(one)


def test_failures_and_bad_input(geometry, targets):
    fix = simulate(EYE, geometry, RIGHT_APEX, targets)
    one = EyeSamples(fix.samples.pupil_px[:1], fix.samples.glints_px[:1])
    result = GuestrinEstimator(geometry).calibrate(one, targets[:1])
    assert isinstance(result, CalibrationFailure) and not result and "1 valid targets" in result.reason
    with pytest.raises(ValueError):
        GuestrinEstimator(geometry).calibrate(fix.samples, targets[:5])
    with pytest.raises(ValueError):
        EyeSamples(np.full((3, 2), np.nan), np.zeros((3, 2, 2)))
    with pytest.raises(ValueError):
        EyeSamples(np.zeros((3, 2)), np.zeros((4, 2, 2)))
    with pytest.raises(ValueError):
        GuestrinEstimator(geometry).calibrate(EyeSamples(fix.samples.pupil_px, fix.samples.glints_px[:, :1]), targets)


def test_invalid_samples_are_skipped(geometry, targets):
    fix = simulate(EYE, geometry, RIGHT_APEX, targets)
    pupil = fix.samples.pupil_px.copy()
    glints = fix.samples.glints_px.copy()
    pupil[4], glints[4] = np.nan, np.nan
    valid = np.ones(9, bool)
    valid[4] = False
    samples = EyeSamples(pupil, glints, valid)
    cal = GuestrinEstimator(geometry).calibrate(samples, targets)
    assert cal.n_targets == 8
    est = cal.estimate(samples)
    assert np.all(np.isnan(est[4])) and np.all(np.isfinite(np.delete(est, 4, axis=0)))
