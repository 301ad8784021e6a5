"""The profile of a later round (`eyehil.analysis.discrepancy.profile`): D minimised over a linear shift of the
earlier effects' parameters, from their conditions at +-h."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.analysis.discrepancy.profile import SHIFT, STEP, Profile, probes
from eyehil.emulator import effects
from eyehil.emulator.effects import Applied

E = 6  # eyes


def _model(seed: int = 0):
    """Two conditions linear in two parameters per eye: m = base + J' theta, and terms (mean - target) / 0.1."""
    rng = np.random.default_rng(seed)
    J = {"a": rng.normal(1.0, 0.2, (2, E)), "b": rng.normal(0.0, 1.0, (2, E))}
    base = {"a": rng.normal(0.0, 0.05, E), "b": rng.normal(0.0, 0.05, E)}
    return J, base


def _terms(target: dict[str, float]):
    return lambda m: np.column_stack([(np.atleast_2d(m[c]).mean(axis=1) - target[c]) / 0.1 for c in sorted(target)])


def test_probes_move_one_parameter_each_within_its_range() -> None:
    tilt = Applied.of(effects.get("screen_tilt"), tilt_deg=5.0, yaw_deg=-1.0)
    roll = Applied.of(effects.get("head_roll"), roll_deg=effects.get("head_roll").parameter("roll_deg").high)
    points, spans, lo, hi = probes([tilt, roll])
    assert len(points) == 2 * 3 and len(spans) == len(lo) == len(hi) == 3
    p_roll = roll.effect.parameter("roll_deg")
    width = p_roll.high - p_roll.low
    assert points[4][1].values["roll_deg"] == p_roll.high  # +h is clipped at the bound: one-sided
    assert points[5][1].values["roll_deg"] == pytest.approx(p_roll.high - STEP * width)
    assert spans[2] == pytest.approx(STEP * width) and hi[2] == 0.0 and lo[2] == pytest.approx(-SHIFT * width)
    assert points[0][0].values["yaw_deg"] == -1.0 and points[0][1] is roll  # the others as they are
    assert all(p[0].values["tilt_deg"] != 5.0 for p in points[:2])


def test_the_profile_finds_the_shift_that_closes_a_linear_gap_and_keeps_its_bounds() -> None:
    J, base = _model()
    theta = np.array([0.3, -0.2])  # the shift hidden in the "measured" targets
    target = {c: float((base[c] + theta @ J[c]).mean()) for c in J}
    h = 0.05
    probed = [{c: base[c] + s * h * np.eye(2)[j] @ J[c] for c in J} for j in range(2) for s in (1, -1)]
    profile = Profile.of(probed, np.full(2, 2 * h), np.full(2, -1.0), np.full(2, 1.0), _terms(target))
    for c in J:
        np.testing.assert_allclose(profile.J[c], J[c], atol=1e-12)
    point = {c: np.stack([base[c], base[c] + 0.1]) for c in J}  # two simulations, the second off by 0.1 in both
    delta = profile.best_shift(point)
    np.testing.assert_allclose(delta[0], theta, atol=1e-6)
    shifted = profile(point)
    assert np.sum(profile.terms(shifted) ** 2, axis=1)[0] == pytest.approx(0.0, abs=1e-8)
    assert np.all(np.sum(profile.terms(shifted) ** 2, axis=1) <= np.sum(profile.terms(point) ** 2, axis=1))
    narrow = Profile.of(probed, np.full(2, 2 * h), np.full(2, -0.1), np.full(2, 0.1), _terms(target))
    assert np.all(np.abs(narrow.best_shift(point)) <= 0.1 + 1e-12)  # the bounds hold
    one = profile.one({c: base[c] for c in J})
    assert set(one) == set(J) and one["a"].shape == (E,)


def test_the_profiles_sigma_is_the_curvature_of_its_linear_terms() -> None:
    """D = |z|^2 with z linear in the shift: Delta D = 1 at sqrt(diag((Jz' Jz)^-1)), Jz the terms' slope."""
    J, base = _model(1)
    target = {"a": 0.2, "b": -0.1}
    h = 0.05
    probed = [{c: base[c] + s * h * np.eye(2)[j] @ J[c] for c in J} for j in range(2) for s in (1, -1)]
    profile = Profile.of(probed, np.full(2, 2 * h), np.full(2, -1.0), np.full(2, 1.0), _terms(target))
    Jz = np.array([[J[c][j].mean() / 0.1 for j in range(2)] for c in sorted(target)])  # (T, k)
    expected = np.sqrt(np.diag(np.linalg.inv(Jz.T @ Jz)))
    np.testing.assert_allclose(profile.sigma(base), expected, rtol=1e-6)
