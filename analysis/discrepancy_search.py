"""Fit effects' parameters to minimise the gap measure D: bounded grids, halving refinements, a quadratic.

Every evaluation is a simulation and a calibration, so the search is small and batched: `search_effects`
runs one `EffectSearch` per effect in lock-step and hands all their points of a stage to one `evaluate`
call (one batched calibration for every effect's points). Per effect, with P = 1 or 2 fitted parameters:

1. Coarse grid: `COARSE[P]` points per parameter over the plausible range [low, high] (9, or 3 x 3).
2. `REFINE` refinements: the neighbours of the best point so far at h = step/2, step/4, step/8 (2 or 8
   points each, clipped to the range).
3. A quadratic D(u) = c + g.u + u.H.u / 2 (u in units of the last h = step/8) fitted by least squares to
   the evaluated points within h of the best (2h or 4h if too few: at a bound); if H is positive definite
   its minimum (kept within that window and the range) is evaluated; the best evaluated point is the
   estimate. The curvature gives a 1-sigma uncertainty sqrt(diag(2 H_theta^-1)) (Delta D = 1, D read as
   a chi-square); NaN if the parabola is not convex or its minimum is on a bound.
4. Alternatives: coarse points more than 1.5 coarse steps away whose D is within 1 of the best (e.g. the
   mirror sign of an effect that only error magnitudes see): the data cannot tell them apart.

Ranking (`EffectFit.score`): D at the estimate plus 2 per fitted parameter (AIC-like, D read as -2 log
likelihood up to a constant). An effect is worth adding only if it lowers D by more than the 95 % point of
chi-square(k) (`EffectFit.passes`), after dividing by the squared scale factor s^2 = max(1, D / (n - k))
(n terms of D): when the model with the effect still misfits far beyond sampling, D's scale is inflated
and so is every drop of D (the scale factor of least squares with an unknown variance; the Particle Data
Group's practice); and only if no fitted parameter ends within `EDGE` (a fraction of its range) of a
bound of its plausible range (`EffectFit.at_edge`): a fit that wants to leave the plausible range is
evidence against the effect, not a measurement of it. The reported 1-sigma uncertainties are multiplied
by s; `EffectFit.ci95` is 1.96 of them. `EffectFit.gof_p` is the goodness of fit of the model with the
effect: P(chi-square(n - k) >= D).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats as sps

from emulator.effects import Applied, Effect

COARSE = {1: 9, 2: 3}
REFINE = 3
EDGE = 0.01


@dataclass(frozen=True, eq=False)
class EffectFit:
    """The fitted effect: every parameter's value, 1-sigma of the fitted ones, D before (D0) and at the fit;
    `n_conditions` is the number of terms of D."""

    effect: Effect
    values: dict[str, float]
    sigma: dict[str, float]
    D: float
    D0: float
    n_conditions: int
    points: np.ndarray  # (G, P) evaluated fitted-parameter values
    Ds: np.ndarray  # (G,) D at each
    alternatives: list[dict[str, float]] = field(default_factory=list)

    @property
    def k(self) -> int:
        return len(self.effect.fitted)

    @property
    def reduction(self) -> float:
        return self.D0 - self.D

    @property
    def explained(self) -> float:
        """Fraction of D removed: (D0 - D) / D0."""
        return self.reduction / self.D0 if self.D0 > 0 else 0.0

    @property
    def score(self) -> float:
        return self.D + 2 * self.k

    @property
    def scale(self) -> float:
        """Misfit scale factor sqrt(max(1, D / (n - k))) (1 when n <= k): how much the remaining gap exceeds
        what sampling alone would leave."""
        dof = self.n_conditions - self.k
        return float(np.sqrt(max(1.0, self.D / dof))) if dof > 0 else 1.0

    @property
    def at_edge(self) -> list[str]:
        """Fitted parameters within `EDGE` of their range's ends (the neutral end excepted: that is "no
        effect", which the drop criterion already refuses)."""
        out = []
        for p in self.effect.fitted:
            v, margin = self.values[p.name], EDGE * (p.high - p.low)
            if (v <= p.low + margin and p.low != p.neutral) or (v >= p.high - margin and p.high != p.neutral):
                out.append(p.name)
        return out

    @property
    def ci95(self) -> dict[str, float]:
        """Half-widths of the 95 % intervals of the fitted parameters (1.96 sigma; NaN if unknown)."""
        return {k: 1.96 * s for k, s in self.sigma.items()}

    @property
    def gof_p(self) -> float:
        """P(chi-square(n - k) >= D): the goodness of fit with this effect (1 with no dof left)."""
        dof = self.n_conditions - self.k
        return float(sps.chi2.sf(self.D, dof)) if dof > 0 else 1.0

    def lowers(self, level: float = 0.95) -> bool:
        """(D0 - D) / scale^2 above the `level` point of chi-square(k)."""
        return self.reduction / self.scale**2 > float(sps.chi2.ppf(level, self.k))

    def passes(self, level: float = 0.95) -> bool:
        """Lowers D enough (`lowers`) and no fitted parameter is at its range's edge."""
        return self.lowers(level) and not self.at_edge

    @property
    def applied(self) -> Applied:
        return Applied(self.effect, dict(self.values))


class EffectSearch:
    """One effect's search as a state machine: `ask()` the next points (None when done), `tell(D)`."""

    def __init__(self, effect: Effect, D0: float, n_conditions: int):
        self.effect, self.D0, self.n_conditions = effect, D0, n_conditions
        params = effect.fitted
        self.lo, self.hi = np.array([p.low for p in params]), np.array([p.high for p in params])
        n = COARSE[len(params)]
        self.step = (self.hi - self.lo) / (n - 1)
        axes = [np.linspace(a, b, n) for a, b in zip(self.lo, self.hi, strict=True)]
        self.coarse = np.array(list(itertools.product(*axes)))
        self.points, self.Ds = np.empty((0, len(params))), np.empty(0)
        self.stage, self.sigma = 0, np.full(len(params), np.nan)
        self._pending = self.coarse

    @property
    def best(self) -> np.ndarray:
        return self.points[np.argmin(self.Ds)]

    def ask(self) -> np.ndarray | None:
        return self._pending

    def tell(self, Ds: np.ndarray) -> None:
        self.points = np.vstack([self.points, self._pending])
        self.Ds = np.concatenate([self.Ds, np.asarray(Ds, float)])
        self._pending = None
        while self._pending is None and self.stage <= REFINE:
            self.stage += 1
            self._pending = self._refinement() if self.stage <= REFINE else self._quadratic()

    def _refinement(self) -> np.ndarray | None:
        h = self.step / 2**self.stage
        offsets = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=len(h))))
        return self._new(np.clip(self.best + offsets * h, self.lo, self.hi))

    def _new(self, cand: np.ndarray) -> np.ndarray | None:
        cand = np.unique(cand, axis=0)
        new = [c for c in cand if not np.any(np.all(np.isclose(self.points, c, atol=1e-12), axis=1))]
        return np.array(new) if new else None

    def _quadratic(self) -> np.ndarray | None:
        h = self.step / 2**REFINE
        best = self.best
        estimate, self.sigma = quadratic_minimum(self.points, self.Ds, best, h, self.lo, self.hi)
        return None if estimate is None else self._new(estimate[None])

    def result(self) -> EffectFit:
        i = int(np.argmin(self.Ds))
        sigma = self.sigma  # the curvature near the best point (NaN if the parabola was not convex)
        fitted = self.effect.fitted
        values = self.effect.values({p.name: float(v) for p, v in zip(fitted, self.points[i], strict=True)})
        n = len(self.coarse)
        far = np.any(np.abs(self.coarse - self.points[i]) > 1.5 * self.step, axis=1) & (self.Ds[:n] < self.Ds[i] + 1)
        alternatives = [{p.name: float(v) for p, v in zip(fitted, c, strict=True)} for c in self.coarse[far]]
        dof = self.n_conditions - len(fitted)
        scale = np.sqrt(max(1.0, self.Ds[i] / dof)) if dof > 0 else 1.0
        return EffectFit(self.effect, values, {p.name: float(s * scale) for p, s in zip(fitted, sigma, strict=True)},
                         float(self.Ds[i]), float(self.D0), self.n_conditions, self.points, self.Ds, alternatives)


def quadratic_minimum(points, Ds, best, h, lo, hi) -> tuple[np.ndarray | None, np.ndarray]:
    """Minimum of a quadratic fitted to the points within h of `best` (widened to 2h, 4h while too few
    for the fit), and its 1-sigma (Delta D = 1); (None, NaN) if not convex."""
    P = len(best)
    pairs = [(a, b) for a in range(P) for b in range(a, P)]
    for width in (1.0, 2.0, 4.0):
        u = (points - best) / h
        near = np.all(np.abs(u) <= width + 1e-9, axis=1)
        u, d = u[near], Ds[near]
        design = np.column_stack([np.ones(len(u)), u, *[u[:, a] * u[:, b] for a, b in pairs]])
        if len(u) >= design.shape[1] and np.linalg.matrix_rank(design) == design.shape[1]:
            break
    else:
        return None, np.full(P, np.nan)
    coef = np.linalg.lstsq(design, d, rcond=None)[0]
    g, H = coef[1:P + 1], np.zeros((P, P))
    for (a, b), c in zip(pairs, coef[P + 1:], strict=True):
        H[a, b] = H[b, a] = 2 * c if a == b else c
    if np.any(np.linalg.eigvalsh(H) <= 0):
        return None, np.full(P, np.nan)
    estimate = np.clip(best + np.clip(-np.linalg.solve(H, g), -width, width) * h, lo, hi)
    sigma = np.sqrt(np.diag(2.0 * np.linalg.inv(H) * np.outer(h, h)))
    on_bound = np.isclose(estimate, lo) | np.isclose(estimate, hi)
    return estimate, np.where(on_bound, np.nan, sigma)


def max_evaluations(effect: Effect) -> int:
    """Evaluations of one effect's search at most: coarse grid, refinements, the quadratic's minimum."""
    P = len(effect.fitted)
    return COARSE[P] ** P + REFINE * (3**P - 1) + 1


def search_effects(effects: Sequence[Effect], evaluate: Callable[[list[Applied]], np.ndarray], D0: float,
                   n_conditions: int) -> list[EffectFit]:
    """Fit every effect; `evaluate(applied list)` returns D for each applied effect (one batch per stage)."""
    searches = [EffectSearch(e, D0, n_conditions) for e in effects]
    while asks := [(s, s.ask()) for s in searches if s.ask() is not None]:
        batch = [Applied.of(s.effect, dict(zip((p.name for p in s.effect.fitted), map(float, row), strict=True)))
                 for s, pts in asks for row in pts]
        Ds = evaluate(batch)
        start = 0
        for s, pts in asks:
            s.tell(Ds[start:start + len(pts)])
            start += len(pts)
    return [s.result() for s in searches]
