"""Twins of the catalogue (`Effect.twins`): effects that no recording can tell apart.

A declared twin must reproduce its effect: at a random strength of the effect, the twin's parameters fitted by
least squares to the effect's per-eye conditions (every gaze and feature condition of the Guestrin 2006
experiment, as from recordings, on 16 eyes of a Rozema 2011 draw) leave in every condition a difference below
`TWIN` of the spread between eyes, while the effect itself moves some condition by more than that spread. Such a
difference is hidden by the eyes' own spread unless a study has over a thousand eyes. An effect that
only resembles another (a tilted cornea for a decentred pupil, a near-mimic in the gaze errors alone) fails the
criterion: the test tells twins from mimics.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from eyehil.analysis.discrepancy.metrics import Evaluator
from eyehil.analysis.discrepancy.trials import draw, outside, recording_conditions
from eyehil.emulator import effects
from eyehil.emulator.effects import Applied
from eyehil.emulator.eye.population import sample

#: the largest difference of twins left in any condition and eye, in units of the spread between eyes: two samples
#: of eyes whose means differ by 0.1 spreads need about 1,600 eyes each to tell apart (5 %, 80 % power)
TWIN = 0.1


@pytest.fixture(scope="module")
def evaluator() -> tuple[Evaluator, list[str]]:
    eyes = sample(16, np.random.default_rng(5)).eyes
    return Evaluator("guestrin2006", eyes, seed=1), recording_conditions("guestrin2006")


def _pairs() -> list[tuple[str, str]]:
    return sorted({tuple(sorted((e, t))) for e in effects.names() for t in effects.get(e).twins})


def _closest(evaluator, conditions, target: Applied, twin_name: str) -> tuple[np.ndarray, np.ndarray, dict]:
    """The twin's values that best reproduce `target`'s conditions, and per condition the largest difference per
    eye left (in units of the spread between eyes) and the target's own largest change, with the values."""
    twin = effects.get(twin_name)

    def stack(metrics) -> np.ndarray:  # (condition, eye)
        return np.array([np.asarray(metrics[c], float) for c in conditions])

    base, goal = (stack(m) for m in evaluator.evaluate([[], [target]]))
    spread = np.nanstd(base, axis=1)
    keep = spread > 0

    def values(x) -> dict[str, float]:
        return {p.name: float(v) for p, v in zip(twin.fitted, x, strict=True)}

    def differences(points) -> list[np.ndarray]:
        got = evaluator.evaluate([[Applied.of(twin, values(x))] for x in points])
        return [np.nan_to_num((stack(g) - goal)[keep] / spread[keep, None]) for g in got]

    # a grid over the twin's plausible range, then Nelder-Mead from its best node (the conditions carry the
    # ray tracer's numerical noise, about 1e-5 spreads: too rough for finite-difference gradients)
    axes = [np.linspace(p.low, p.high, 7) for p in twin.fitted]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    start = grid[np.argmin([(d**2).sum() for d in differences(grid)])]
    box = [(p.low, p.high) for p in twin.fitted]
    fit = minimize(lambda x: float((differences([x])[0] ** 2).sum()), start, method="Nelder-Mead", bounds=box,
                   options={"xatol": 1e-3, "fatol": 1e-4, "maxfev": 120})
    left = np.abs(differences([fit.x])[0]).max(axis=1)
    own = np.nanmax(np.abs(goal - base)[keep] / spread[keep, None], axis=1)
    return left, own, values(fit.x)


def test_twins_are_registered_effects_declared_both_ways() -> None:
    assert _pairs(), "the catalogue declares no twins"
    for name in effects.names():
        for twin in effects.get(name).twins:
            assert twin != name and twin in effects.names(), (name, twin)
            assert name in effects.get(twin).twins, f"{twin} does not name {name} its twin"
    assert outside(effects.get("pupil_decentre")) == {"pupil_decentre", "cornea_decentre"}


def _narrower_first(pair: tuple[str, str]) -> tuple[str, str]:
    width = {n: sum(p.high - p.low for p in effects.get(n).fitted) for n in pair}
    return tuple(sorted(pair, key=width.get))


@pytest.mark.parametrize("pair", _pairs(), ids="-".join)
def test_a_twin_reproduces_every_condition_of_its_effect_and_back(evaluator, pair) -> None:
    """The effect of the narrower plausible range drawn at a random strength (its match lies inside the wider
    one's range), its twin fitted to it, and the effect fitted back to the twin at those values: both matches
    leave less than TWIN in every condition, and the way back returns the drawn values."""
    ev, conditions = evaluator
    name, twin = _narrower_first(pair)
    target = Applied.of(effects.get(name), draw(effects.get(name), np.random.default_rng(3)))
    left, own, matched = _closest(ev, conditions, target, twin)
    assert own.max() > 1.0, f"{target.label()} moves no condition by a spread between eyes"
    assert left.max() < TWIN, f"{twin} {matched} leaves {left.max():.3f} spreads of {target.label()}"
    back_left, _, back = _closest(ev, conditions, Applied.of(effects.get(twin), matched), name)
    assert back_left.max() < TWIN, f"{name} {back} leaves {back_left.max():.3f} spreads of {twin} {matched}"
    assert back == pytest.approx(dict(target.values), abs=0.01)


def test_a_mimic_in_the_gaze_errors_is_not_a_twin(evaluator) -> None:
    ev, conditions = evaluator
    target = Applied.of(effects.get("pupil_decentre"), nasal_mm=-0.28, superior_mm=0.51)
    left, _, values = _closest(ev, conditions, target, "cornea_tilt")
    assert left.max() > 10 * TWIN, f"cornea_tilt {values} reproduces {target.label()} to {left.max():.3f} spreads"
