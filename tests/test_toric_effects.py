"""The anatomy effects of issue 13 (emulator/effects/anatomy.py): registration entries, identity at neutral
values, and what each changes."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from eyehil.emulator.effects.anatomy import ANATOMY_EFFECTS
from eyehil.emulator.eye.astigmatism import ANTERIOR_DN, POSTERIOR_DN, power_vector
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene


def _effect(name: str):
    module, cls = ANATOMY_EFFECTS[name].split(":")
    effect = getattr(importlib.import_module(module), cls)()
    assert effect.name == name and effect.reference and effect.summary()
    return effect


@pytest.fixture(scope="module")
def eyes():
    return published_eyes()[:4]


@pytest.mark.parametrize("name", list(ANATOMY_EFFECTS))
def test_identity_at_neutral_values(eyes, name: str) -> None:
    effect = _effect(name)
    scene = load_scene("guestrin2006")
    for session in ("calibration", "validation"):
        out, same_scene = effect.apply(eyes, scene, effect.values(effect.neutral()), session)
        assert out is eyes and same_scene is scene


def test_corneal_astigmatism_adds_power_vectors_and_keeps_the_mean_power(eyes) -> None:
    effect = _effect("corneal_astigmatism")
    values = effect.values(anterior_j0_d=0.5, anterior_j45_d=-0.2, posterior_j0_d=-0.15)
    once, _ = effect.apply(eyes, load_scene("guestrin2006"), values, "calibration")
    twice, _ = effect.apply(once, load_scene("guestrin2006"), values, "calibration")
    m, j0, j45 = power_vector(twice.anterior_radius, twice.anterior_radius_perp, twice.anterior_axis_deg, ANTERIOR_DN)
    np.testing.assert_allclose(j0, 1.0, atol=1e-12)
    np.testing.assert_allclose(j45, -0.4, atol=1e-12)
    np.testing.assert_allclose(m, 337.2 / eyes.anterior_radius, rtol=1e-13)
    _, pj0, pj45 = power_vector(twice.posterior_radius, twice.posterior_radius_perp, twice.posterior_axis_deg,
                                POSTERIOR_DN)
    np.testing.assert_allclose([pj0, pj45], [np.full(4, -0.3), np.zeros(4)], atol=1e-12)


@pytest.mark.parametrize(("name", "values"), [
    ("corneal_astigmatism", {"anterior_j0_d": 0.75}), ("cornea_tilt", {"nasal_deg": 2.5}),
    ("cornea_decentre", {"nasal_mm": 0.3, "superior_mm": -0.2}), ("pupil_ellipse", {"eccentricity": 0.3}),
])
def test_each_effect_moves_the_features(eyes, name: str, values: dict) -> None:
    effect = _effect(name)
    scene = load_scene("guestrin2006")
    changed, _ = effect.apply(eyes, scene, effect.values(values), "validation")
    assert not changed.rotationally_symmetric.any()
    base, moved = simulate(eyes, scene), simulate(changed, scene)
    assert moved.valid.all()
    shift = np.abs(moved.pupil_centre_px - base.pupil_centre_px).max() + np.abs(moved.glint_px - base.glint_px).max()
    assert shift > 0.01  # px
