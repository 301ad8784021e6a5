"""Each Guestrin estimator option against a known answer: a spherical cornea (the forms agree) and an
aspheric one (they differ in the documented direction)."""

from __future__ import annotations

import numpy as np
import pytest
from spherical_eye import RIGHT_APEX, SphericalEye, guestrin_geometry, simulate

from eyehil.analysis.study.bridge import eye_samples, screen_targets, tracker_geometry
from eyehil.drivers.gaze.base import EyeSamples
from eyehil.drivers.gaze.cornea import corneal_centre
from eyehil.drivers.gaze.guestrin import (
    PROFILES,
    EyeParameters,
    GuestrinEstimator,
    GuestrinOptions,
    gaze_error_deg,
    gaze_plane,
    point_of_gaze,
    profile,
    visual_axis,
)
from eyehil.drivers.gaze.guestrin_batch import calibrate_many
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate as ray_trace
from eyehil.emulator.scene import load_scene

EYE = SphericalEye(R=7.6, K=4.4, alpha_deg=5.3, beta_deg=1.8)


@pytest.fixture(scope="module")
def geometry():
    return guestrin_geometry()


@pytest.fixture(scope="module")
def targets(geometry):
    return geometry.screen.grid(3, 3).reshape(-1, 2)


@pytest.fixture(scope="module")
def spherical(geometry, targets):
    return simulate(EYE, geometry, RIGHT_APEX, targets)


@pytest.fixture(scope="module")
def aspheric():
    """Ray-traced features (emulator) of one published eye, with its cornea made spherical or prolate."""
    scene = load_scene("guestrin2006")
    eye = published_eyes()[3:4]
    out = {}
    for q in (0.0, -0.45):
        e = eye.replace(anterior_conic=np.full(1, q))  # a conic of revolution: its _perp twin follows
        f = ray_trace(e, scene)
        s = eye_samples(f, "right")
        out[q] = EyeSamples(s.pupil_px[0, 0], s.glints_px[0, 0], s.valid[0, 0])
    return tracker_geometry(scene), screen_targets(scene), out, float(eye.anterior_radius[0])


def test_profiles_are_the_documented_options() -> None:
    study = profile("study-code")
    assert (study.corneal_distance, study.visual_axis, study.gaze_plane_offset_mm, study.error_metric, study.n1,
            study.objective) == (0, "rotation", 1.0, "3-d", 1.376, "sum-of-errors")
    assert PROFILES["best"] == GuestrinOptions()
    for bad in ({"corneal_distance": "one"}, {"visual_axis": "euler"}, {"error_metric": "2-d"},
                {"objective": "median"}, {"gaze_plane_offset_mm": float("nan")}, {"n1": 0.5}):
        with pytest.raises(ValueError):
            GuestrinOptions(**bad)
    with pytest.raises(ValueError):
        profile("fastest")


# --- corneal distance ----------------------------------------------------------------------------------------


def test_corneal_distance_spherical_every_form_finds_the_centre(geometry, spherical) -> None:
    for distance in ("all-glints", 0, 1):
        c = corneal_centre(geometry.camera, geometry.leds, spherical.samples.glints_px, EYE.R, distance)
        np.testing.assert_allclose(c, spherical.c, atol=1e-6)


def test_corneal_distance_aspheric_one_glint_carries_the_bias(aspheric) -> None:
    """Prolate cornea (Q < 0): the forms separate; the one-glint fit's calibration error is the larger."""
    geometry, targets, features, radius = aspheric
    c = {d: corneal_centre(geometry.camera, geometry.leds, features[0.0].glints_px, radius, d)
         for d in ("all-glints", 0)}
    np.testing.assert_allclose(c[0], c["all-glints"], atol=1e-5)  # sphere: identical
    c = {d: corneal_centre(geometry.camera, geometry.leds, features[-0.45].glints_px, radius, d)
         for d in ("all-glints", 0, 1)}
    o = geometry.camera.o
    k = {d: np.linalg.norm(v - o, axis=-1) for d, v in c.items()}
    assert np.all(np.abs(k[0] - k["all-glints"]) > 1e-3)
    # least squares lies between the two glints' own roots
    assert np.all((k["all-glints"] - k[0]) * (k["all-glints"] - k[1]) < 0)
    h1 = {}
    for d in ("all-glints", 0):
        fit = calibrate_many(geometry, _batch(features[-0.45]), targets, options=GuestrinOptions(corneal_distance=d))
        h1[d] = float(fit.errors_deg(_batch(features[-0.45]), targets).mean())
    assert h1[0] > h1["all-glints"]


def _batch(s: EyeSamples) -> EyeSamples:
    return EyeSamples(s.pupil_px[None], s.glints_px[None], s.valid[None])


# --- visual axis ---------------------------------------------------------------------------------------------


def test_visual_axis_forms_agree_straight_ahead_and_rotation_keeps_the_angle() -> None:
    ahead = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(visual_axis(ahead, 5.0, 1.5, "rotation"), visual_axis(ahead, 5.0, 1.5), atol=1e-15)
    expected = [np.cos(np.radians(1.5)) * np.sin(np.radians(5.0)), np.sin(np.radians(1.5)),
                np.cos(np.radians(1.5)) * np.cos(np.radians(5.0))]
    np.testing.assert_allclose(visual_axis(ahead, 5.0, 1.5, "rotation"), expected, atol=1e-15)
    # away from straight ahead: the rotation form is one rigid rotation of every optic axis (it keeps the angle
    # between any two gaze directions); angle addition is not, and the two part by hundredths of a degree at the
    # screen's corners (optic axis about 16 deg sideways and 13 deg up)
    th, ph = np.radians(np.array([16.0, -16.0, 3.0])), np.radians(np.array([13.0, -13.0, 20.0]))
    w = np.stack([np.cos(ph) * np.sin(th), np.sin(ph), np.cos(ph) * np.cos(th)], axis=-1)
    rot, add = visual_axis(w, 5.0, 1.5, "rotation"), visual_axis(w, 5.0, 1.5)
    np.testing.assert_allclose(rot @ rot.T, w @ w.T, atol=1e-14)
    assert np.abs(add @ add.T - w @ w.T).max() > 1e-6
    apart = np.degrees(np.arccos(np.clip(np.sum(rot * add, axis=-1), -1, 1)))
    assert np.all((apart[:2] > 0.01) & (apart[:2] < 0.2))
    with pytest.raises(ValueError):
        visual_axis(w, 5.0, 1.5, "euler")


# --- gaze plane and error metric -----------------------------------------------------------------------------


def test_gaze_plane_offset_and_3d_error_known_answer(geometry, spherical, targets) -> None:
    params = EyeParameters(EYE.R, EYE.K, EYE.alpha_deg, EYE.beta_deg, EYE.n1)
    on_screen = point_of_gaze(geometry, spherical.samples, params)
    np.testing.assert_allclose(on_screen, targets, atol=1e-6)  # spherical, exact model: exact gaze
    options = GuestrinOptions(gaze_plane_offset_mm=1.0, error_metric="3-d")
    behind = point_of_gaze(geometry, spherical.samples, params, options=options)
    nu = (geometry.screen.to_world(targets) - spherical.c)
    shift = nu[:, :2] / nu[:, 2:3]  # 1 mm further along z moves the point by (nu_x, nu_y) / nu_z
    np.testing.assert_allclose(behind - on_screen, shift, atol=1e-6)
    assert gaze_plane(geometry, 1.0).centre[2] == pytest.approx(651.0)
    np.testing.assert_allclose(gaze_error_deg(targets, targets, options), np.degrees(np.arctan(1 / 650)), rtol=1e-12)
    np.testing.assert_allclose(gaze_error_deg(targets + np.array([3.0, 4.0]), targets, options),
                               np.degrees(np.arctan(np.sqrt(26.0) / 650)), rtol=1e-12)
    np.testing.assert_allclose(gaze_error_deg(targets + np.array([3.0, 4.0]), targets), np.degrees(np.arctan(5 / 650)))


# --- pupil index and objective -------------------------------------------------------------------------------


@pytest.mark.parametrize("objective", ["screen", "angular", "sum-of-errors"])
def test_objectives_recover_a_spherical_eye(geometry, spherical, targets, objective) -> None:
    options = GuestrinOptions(objective=objective)
    fit = calibrate_many(geometry, _batch(spherical.samples), targets, options=options)
    np.testing.assert_allclose(fit.params[0], [EYE.R, EYE.K, EYE.alpha_deg, EYE.beta_deg], atol=2e-3)
    assert fit.errors_deg(_batch(spherical.samples), targets).max() < 1e-4


def test_pupil_index_exact_only_when_it_matches(geometry, spherical, targets) -> None:
    right = calibrate_many(geometry, _batch(spherical.samples), targets, options=GuestrinOptions(n1=EYE.n1))
    wrong = calibrate_many(geometry, _batch(spherical.samples), targets, options=GuestrinOptions(n1=1.376))
    assert right.errors_deg(_batch(spherical.samples), targets).max() < 1e-4
    assert abs(wrong.params[0, 1] - EYE.K) > 0.05  # K absorbs the index


def test_objectives_differ_on_an_aspheric_cornea_as_documented(aspheric) -> None:
    """Each objective's fit is the better one by its own measure: the sum-of-errors fit has the lower sum of
    errors, the least-squares fit the lower sum of squared on-screen residuals."""
    geometry, targets, features, _ = aspheric
    s = _batch(features[-0.45])
    fits = {o: calibrate_many(geometry, s, targets, options=GuestrinOptions(objective=o))
            for o in ("screen", "sum-of-errors")}
    err = {o: f.errors_deg(s, targets)[0] for o, f in fits.items()}
    sq = {o: np.sum((f.estimate(s)[0] - targets) ** 2) for o, f in fits.items()}
    assert err["sum-of-errors"].sum() < err["screen"].sum()
    assert sq["screen"] < sq["sum-of-errors"]


def test_estimator_profiles_and_scipy_reference_agree(geometry, spherical, targets) -> None:
    """The per-eye estimator with a profile reaches the batched calibration's minimum."""
    est = GuestrinEstimator.from_profile(geometry, "best")
    fit = est.calibrate(spherical.samples, targets)
    batch = calibrate_many(geometry, _batch(spherical.samples), targets, options="best")
    np.testing.assert_allclose([fit.parameters.R, fit.parameters.K], batch.params[0, :2], atol=1e-4)
    assert GuestrinEstimator.from_profile(geometry, "study-code").n1 == 1.376
