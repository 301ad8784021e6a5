"""Blignaut 2014 interpolation: the forms catalogue, exact fits, failures and binocular averaging."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.drivers.gaze.base import BinocularSamples, CalibrationFailure, EyeSamples
from eyehil.drivers.gaze.blignaut import BlignautEstimator, fit_form, normalised_pupil_glint
from eyehil.drivers.gaze.forms import FORMS, MODELS, describe, design_matrix, resolve_form

TERMS = {1: (2, 2), 2: (4, 4), 3: (6, 6), 4: (7, 7), 5: (4, 4), 6: (4, 5), 7: (5, 7), 8: (8, 7)}


def random_binocular(rng: np.random.Generator, n: int, same_features: bool = False) -> BinocularSamples:
    """Pupils about 450 px apart, pupil-glint vectors of a few to 30 px (features about +-0.07)."""
    right_pupil = rng.uniform([500, 500], [560, 540], (n, 2))
    left_pupil = right_pupil + rng.uniform([430, -5], [470, 5], (n, 2))
    right_glint = right_pupil - rng.uniform(-30, 30, (n, 2))
    left_vector = right_pupil - right_glint if same_features else rng.uniform(-30, 30, (n, 2))
    left_glint = left_pupil - left_vector
    return BinocularSamples(EyeSamples(right_pupil, right_glint[:, None]), EyeSamples(left_pupil, left_glint[:, None]))


def polynomial_targets(rng, model: int, features: np.ndarray) -> np.ndarray:
    """Screen mm from random coefficients of model's forms: each term contributes about 10-100 mm."""
    out = []
    for name in MODELS[model]:
        form = FORMS[name]
        A = design_matrix(form, features)
        coef = rng.uniform(10, 100, len(form)) * rng.choice([-1, 1], len(form)) / np.abs(A).max(axis=0)
        out.append(A @ coef)
    return np.stack(out, axis=-1)


def test_catalogue_matches_reference_table():
    assert describe(FORMS["X1"]) == "1 + x" and describe(FORMS["Y1"]) == "1 + y"
    assert describe(FORMS["X4"]) == "1 + x + y + xy + x^2 + y^2 + x^2y^2"
    assert describe(FORMS["Y5"]) == "1 + x + y + y^2"
    assert describe(FORMS["X5"]) == "1 + x + y + x^2" and describe(FORMS["Y6"]) == "1 + y + x^2 + xy + x^2y"
    assert describe(FORMS["X6"]) == "1 + x + x^3 + y^2 + xy"
    assert describe(FORMS["Y7"]) == "1 + x + x^2 + y + y^2 + xy + x^2y"
    assert describe(FORMS["X7"]) == "1 + x + x^2 + x^3 + y + xy + x^2y + x^3y"
    assert FORMS["X2"] == FORMS["Y2"] and FORMS["X3"] == FORMS["Y3"] and FORMS["X4"] == FORMS["Y4"]
    assert {k: (len(FORMS[x]), len(FORMS[y])) for k, (x, y) in MODELS.items()} == TERMS


def test_features_known_answer():
    right = EyeSamples(np.array([[100.0, 200.0]]), np.array([[[90.0, 195.0]]]))
    left = EyeSamples(np.array([[400.0, 200.0]]), np.array([[[403.0, 206.0]]]))
    r, left_v = normalised_pupil_glint(BinocularSamples(right, left))
    np.testing.assert_allclose(r, [[10 / 300, 5 / 300]])
    np.testing.assert_allclose(left_v, [[-3 / 300, -6 / 300]])


@pytest.mark.parametrize("name", sorted(FORMS))
def test_fit_form_recovers_coefficients(name):
    rng = np.random.default_rng(7)
    form = FORMS[name]
    features = rng.uniform(-0.07, 0.07, (40, 2))
    A = design_matrix(form, features)
    coef = rng.normal(size=len(form)) * 50 / np.abs(A).max(axis=0)
    fitted = fit_form(form, features, A @ coef)
    np.testing.assert_allclose(fitted, coef, rtol=1e-8)
    np.testing.assert_allclose(A @ fitted, A @ coef, atol=1e-9)


@pytest.mark.parametrize("model", sorted(MODELS))
def test_each_model_fits_its_own_polynomial(model):
    rng = np.random.default_rng(model)
    samples = random_binocular(rng, 23, same_features=True)
    features, _ = normalised_pupil_glint(samples)
    targets = polynomial_targets(rng, model, features)
    cal = BlignautEstimator.from_model(model).calibrate(samples, targets)
    assert cal and cal.n_targets == 23
    np.testing.assert_allclose(cal.estimate(samples), targets, atol=1e-9)
    assert max(cal.rms_mm.values()) < 1e-9
    fresh = random_binocular(rng, 50, same_features=True)
    f_new, _ = normalised_pupil_glint(fresh)
    x_form, y_form = (FORMS[n] for n in MODELS[model])
    expected = np.stack([design_matrix(x_form, f_new) @ cal.coefficients["right"]["x"],
                         design_matrix(y_form, f_new) @ cal.coefficients["right"]["y"]], -1)
    np.testing.assert_allclose(cal.estimate(fresh), expected, atol=1e-9)


def test_binocular_average_of_per_eye_least_squares():
    rng = np.random.default_rng(3)
    samples = random_binocular(rng, 30)
    targets = rng.uniform([-240, -140], [240, 140], (30, 2))
    cal = BlignautEstimator.from_model(3).calibrate(samples, targets)
    right, left = cal.estimate_per_eye(samples)
    np.testing.assert_allclose(cal.estimate(samples), 0.5 * (right + left), atol=1e-12)
    for est, feats in zip((right, left), normalised_pupil_glint(samples), strict=True):
        A = design_matrix(FORMS["X3"], feats)
        manual = A @ np.linalg.lstsq(A, targets, rcond=None)[0]
        np.testing.assert_allclose(est, manual, atol=1e-8)


def test_too_few_targets_or_rank_deficient_is_a_failure():
    rng = np.random.default_rng(5)
    samples = random_binocular(rng, 5)
    targets = rng.uniform(-100, 100, (5, 2))
    result = BlignautEstimator.from_model(8).calibrate(samples, targets)
    assert isinstance(result, CalibrationFailure) and not result
    assert "5 targets for 8 terms" in result.reason
    assert BlignautEstimator.from_model(1).calibrate(samples, targets)
    assert BlignautEstimator.from_model(8, underdetermined="minimum_norm").calibrate(samples, targets)
    flat = random_binocular(rng, 9)
    glints = flat.right.glints_px.copy()
    ipd = np.linalg.norm(flat.right.pupil_px - flat.left.pupil_px, axis=-1)
    glints[:, 0, 1] = flat.right.pupil_px[:, 1] - 0.01 * ipd  # y feature constant: y and 1 collinear
    flat = BinocularSamples(EyeSamples(flat.right.pupil_px, glints), flat.left)
    rank = BlignautEstimator.from_model(2).calibrate(flat, rng.uniform(-100, 100, (9, 2)))
    assert not rank and "rank-deficient" in rank.reason and "right eye" in rank.reason


def test_invalid_fixations_and_bad_input():
    rng = np.random.default_rng(11)
    samples = random_binocular(rng, 12)
    valid = np.ones(12, bool)
    valid[3] = False
    pupil = samples.left.pupil_px.copy()
    pupil[3] = np.nan
    samples = BinocularSamples(samples.right, EyeSamples(pupil, samples.left.glints_px, valid))
    targets = rng.uniform(-100, 100, (12, 2))
    cal = BlignautEstimator.from_model(2).calibrate(samples, targets)
    assert cal.n_targets == 11
    est = cal.estimate(samples)
    assert np.all(np.isnan(est[3])) and np.all(np.isfinite(np.delete(est, 3, axis=0)))
    with pytest.raises(ValueError):
        BlignautEstimator.from_model(2).calibrate(samples, targets[:5])
    with pytest.raises(ValueError):
        BlignautEstimator("X1", "nope")
    with pytest.raises(ValueError):
        BlignautEstimator.from_model(12)
    with pytest.raises(ValueError):
        resolve_form(((0, 0), (0, 0)))


def test_user_forms():
    rng = np.random.default_rng(2)
    forms = {**FORMS, "Y8": ((0, 0), (0, 1), (0, 3), (1, 2))}
    samples = random_binocular(rng, 15, same_features=True)
    features, _ = normalised_pupil_glint(samples)
    y = design_matrix(forms["Y8"], features) @ np.array([3.0, 900.0, 1e5, -4e4])
    x = design_matrix(FORMS["X1"], features) @ np.array([1.0, 2000.0])
    estimator = BlignautEstimator.from_model(9, forms=forms, models={9: ("X1", "Y8")})
    cal = estimator.calibrate(samples, np.stack([x, y], -1))
    np.testing.assert_allclose(cal.estimate(samples), np.stack([x, y], -1), atol=1e-9)
    direct = BlignautEstimator(((0, 0), (1, 0)), forms["Y8"]).calibrate(samples, np.stack([x, y], -1))
    np.testing.assert_allclose(direct.estimate(samples), cal.estimate(samples), atol=1e-12)
