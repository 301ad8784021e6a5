"""The batched Guestrin calibration (`eyehil.drivers.gaze.guestrin_batch`) against the per-eye estimator on the
published eyes, and its batch independence and failure handling."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.analysis.study.bridge import eye_samples, screen_targets, tracker_geometry
from eyehil.drivers.gaze.base import EyeSamples
from eyehil.drivers.gaze.guestrin import GuestrinEstimator
from eyehil.drivers.gaze.guestrin_batch import calibrate_many
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene

N_EYES = 8


@pytest.fixture(scope="module")
def study():
    scene = load_scene("guestrin2006")
    s = eye_samples(simulate(published_eyes()[:N_EYES], scene), "right")
    return tracker_geometry(scene), screen_targets(scene), s


def _central(s: EyeSamples, index=slice(None)) -> EyeSamples:
    return EyeSamples(s.pupil_px[index, 0], s.glints_px[index, 0], s.valid[index, 0])


def test_batched_equals_the_per_eye_estimator_to_1e_6_deg(study) -> None:
    """Least squares ("best"): scipy's least_squares per eye and the batched LM reach the same minimum."""
    geometry, targets, s = study
    batch = calibrate_many(geometry, _central(s), targets, options="best")
    errors = batch.errors_deg(s, targets)
    estimator = GuestrinEstimator.from_profile(geometry, "best")
    for i in range(N_EYES):
        fit = estimator.calibrate(EyeSamples(s.pupil_px[i, 0], s.glints_px[i, 0], s.valid[i, 0]), targets)
        every = EyeSamples(s.pupil_px[i], s.glints_px[i], s.valid[i])
        reference = fit.errors_deg(every, targets)
        # the study's results, H1 (central) and H2 (moved), to 1e-6 deg; single fixations to 2e-5 deg: the
        # minimum is flat along R-K, where the two solvers' last steps differ by ~1e-5 mm. Measured on the code
        # of 2026-12-02: moving every feature by 1e-10 px (random) moved the worst single fixation's difference
        # between 5e-6 and 1.13e-5 deg over three draws; 1e-5 was the solvers' stopping noise, not a margin.
        assert abs(np.mean(errors[i, 0]) - np.mean(reference[0])) <= 1e-6
        assert abs(np.nanmean(errors[i, 1:]) - np.nanmean(reference[1:])) <= 1e-6
        np.testing.assert_allclose(errors[i], reference, atol=2e-5)
        assert batch.cost[i] <= fit.cost * (1 + 1e-9)


@pytest.mark.parametrize("profile", ["best", "study-code"])
def test_an_eye_alone_equals_the_eye_in_a_batch(study, profile) -> None:
    geometry, targets, s = study
    batch = calibrate_many(geometry, _central(s), targets, options=profile)
    for i in (0, N_EYES - 1):
        alone = calibrate_many(geometry, _central(s, slice(i, i + 1)), targets, options=profile)
        np.testing.assert_allclose(alone.params[0], batch.params[i], rtol=1e-12, atol=1e-12)


def test_study_code_profile_reaches_at_least_the_per_eye_minimum(study) -> None:
    """Sum of errors: the batched fit's objective is no worse than the per-eye L-BFGS-B's (to 1e-6 deg)."""
    geometry, targets, s = study
    batch = calibrate_many(geometry, _central(s, slice(0, 2)), targets, options="study-code")
    estimator = GuestrinEstimator.from_profile(geometry, "study-code")
    for i in range(2):
        fit = estimator.calibrate(EyeSamples(s.pupil_px[i, 0], s.glints_px[i, 0], s.valid[i, 0]), targets)
        assert batch.cost[i] <= fit.cost + 1e-6


def test_impossible_calibrations_are_named(study) -> None:
    geometry, targets, s = study
    central = _central(s, slice(0, 3))
    valid = central.valid.copy()
    valid[1, 1:] = False
    samples = EyeSamples(np.where(valid[..., None], central.pupil_px, np.nan),
                         np.where(valid[..., None, None], central.glints_px, np.nan), valid)
    fit = calibrate_many(geometry, samples, targets)
    assert list(fit.reasons) == [1] and "valid targets" in fit.reasons[1]
    assert np.isnan(fit.params[1]).all() and np.isfinite(fit.params[[0, 2]]).all()
    assert np.isnan(fit.estimate(_central(s, slice(0, 3)))[1]).all()
    with pytest.raises(ValueError):
        calibrate_many(geometry, EyeSamples(s.pupil_px[:, 0, 0], s.glints_px[:, 0, 0]), targets[0])
