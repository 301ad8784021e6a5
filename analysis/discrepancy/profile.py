"""A later round's candidates scored with the earlier rounds' effects free: D profiled over a linear shift of
their fitted parameters, at two simulations per parameter.

Round 1 fits the first effect while the second's gap is still open, so the first takes up part of the second's
gap, and round 2 fits the second against a biased first. Where two effects partly cancel, that bias can hide the
second altogether: a head roll fitted at -3.9 deg beside a screen tilt (hidden roll -6.0 deg) left the tilt outside
round 2's first five, where with the roll at its hidden value round 2 names the tilt at once (D 320.8 -> 25.4;
docs/blind-trials.md, 22nd session). Fitting the two together costs a grid over both; this reads the first effect's
parameters as free near their fit instead, by a linear model of what they do to the conditions:

    m(theta + delta) ~ m(theta) + J delta,

per eye and condition, J by central differences over h = `STEP` of each parameter's plausible range (one-sided at a
bound). A candidate's point (its conditions m_point, simulated with the earlier effects at theta) is scored at the
delta that minimises D of m_point + J delta: Gauss-Newton on the signed terms of D (`ITERATIONS` steps, each kept
only where it lowers D), delta within `SHIFT` of each range and inside the range. The linear model assumes the
candidate does not change J (their interaction is second order); the workflow's backfit then refits every added
effect with true simulations, so the profile only decides which candidate a round adds and where its search
looks, not the reported fits.

Conditions are dicts of per-eye values, (P, E) for P simulations (`eyehil.analysis.discrepancy.metrics`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.effects import Applied

Metrics = dict[str, np.ndarray]

STEP = 1.0 / 16  # the central difference's h, a fraction of each parameter's plausible range
SHIFT = 0.25  # the largest shift, a fraction of each parameter's plausible range
ITERATIONS = 3  # Gauss-Newton steps
EPS = 1.0 / 256  # the terms' finite difference, a fraction of each parameter's range


def probes(added: Sequence[Applied]) -> tuple[list[list[Applied]], np.ndarray, np.ndarray, np.ndarray]:
    """The points whose conditions give J: for each fitted parameter of the `added` effects, the whole list of
    added effects with that parameter at +h and -h (inside its range); and per parameter the two values' distance
    (the divisor of the difference), the shift's lower and upper bounds."""
    points, spans, lo, hi = [], [], [], []
    for i, applied in enumerate(added):
        for p in applied.effect.fitted:
            value, width = applied.values[p.name], p.high - p.low
            up, down = min(p.high, value + STEP * width), max(p.low, value - STEP * width)
            for v in (up, down):
                moved = Applied(applied.effect, {**applied.values, p.name: float(v)})
                points.append([*added[:i], moved, *added[i + 1:]])
            spans.append(up - down)
            lo.append(max(p.low - value, -SHIFT * width))
            hi.append(min(p.high - value, SHIFT * width))
    return points, np.array(spans), np.array(lo), np.array(hi)


@dataclass(frozen=True)
class Profile:
    """The linear model of the earlier effects' parameters (module docstring) and D's terms to minimise."""

    J: Metrics  # condition -> (k, E): d condition / d parameter, per eye
    lo: np.ndarray  # (k,) the shift's bounds, parameter units
    hi: np.ndarray
    terms: Callable[[Metrics], np.ndarray]  # conditions (P, E) -> the signed terms of D (P, T)

    @classmethod
    def of(cls, probed: Sequence[Metrics], spans: np.ndarray, lo: np.ndarray, hi: np.ndarray,
           terms: Callable[[Metrics], np.ndarray]) -> Profile:
        """From the conditions of `probes`' points, in their order (+h, -h per parameter)."""
        J = {}
        for c in probed[0]:
            rows = [(np.asarray(probed[2 * j][c], float) - np.asarray(probed[2 * j + 1][c], float)) / spans[j]
                    for j in range(len(spans))]
            J[c] = np.nan_to_num(np.array(rows), nan=0.0, posinf=0.0, neginf=0.0)
        return cls(J, lo, hi, terms)

    def shift(self, metrics: Metrics, delta: np.ndarray) -> Metrics:
        """Conditions (P, E) moved by shifts `delta` (P, k)."""
        return {c: (v + delta @ self.J[c]) if c in self.J else v for c, v in metrics.items()}

    def best_shift(self, metrics: Metrics) -> np.ndarray:
        """The shift (P, k) that minimises D of each simulation's shifted conditions (module docstring)."""
        metrics = {c: np.atleast_2d(np.asarray(v, float)) for c, v in metrics.items()}
        P, k = len(next(iter(metrics.values()))), len(self.lo)
        delta = np.zeros((P, k))
        z = self._terms(metrics, delta)
        D = np.sum(z**2, axis=1)
        eps = EPS * (self.hi - self.lo) / (2 * SHIFT)  # EPS of the range, or half that where a bound cuts the shift
        for _ in range(ITERATIONS):
            Jz = self._slope(metrics, delta, z, eps)
            A = np.einsum("ptj,ptl->pjl", Jz, Jz) + 1e-12 * np.eye(k)
            g = np.einsum("ptj,pt->pj", Jz, z)
            try:
                step = -np.linalg.solve(A, g[..., None])[..., 0]
            except np.linalg.LinAlgError:
                break
            trial = np.clip(delta + np.nan_to_num(step), self.lo, self.hi)
            z_trial = self._terms(metrics, trial)
            D_trial = np.sum(z_trial**2, axis=1)
            better = D_trial < D
            delta, z, D = np.where(better[:, None], trial, delta), np.where(better[:, None], z_trial, z), \
                np.where(better, D_trial, D)
        return delta

    def sigma(self, metrics: Metrics) -> np.ndarray:
        """1-sigma of the parameters at the profile's own point, from one simulation's conditions (E,) there: D
        read as a chi-square, Delta D = 1, sqrt(diag((Jz' Jz)^-1)) with Jz the slope of D's terms; NaN where Jz' Jz
        is singular."""
        metrics = {c: np.atleast_2d(np.asarray(v, float)) for c, v in metrics.items()}
        k = len(self.lo)
        z = self._terms(metrics, np.zeros((1, k)))
        Jz = self._slope(metrics, np.zeros((1, k)), z, EPS * (self.hi - self.lo) / (2 * SHIFT))[0]  # (T, k)
        try:
            cov = np.linalg.inv(Jz.T @ Jz)
        except np.linalg.LinAlgError:
            return np.full(k, np.nan)
        return np.sqrt(np.clip(np.diag(cov), 0.0, None))

    def __call__(self, metrics: Metrics) -> Metrics:
        """Conditions (P, E) at each simulation's best shift."""
        metrics = {c: np.atleast_2d(np.asarray(v, float)) for c, v in metrics.items()}
        return self.shift(metrics, self.best_shift(metrics))

    def one(self, metrics: Metrics) -> Metrics:
        """One simulation's conditions (E,) at its best shift."""
        return {c: v[0] for c, v in self(metrics).items()}

    def _slope(self, metrics: Metrics, delta: np.ndarray, z: np.ndarray, eps: np.ndarray) -> np.ndarray:
        """d terms / d shift (P, T, k) at shifts `delta` (P, k), where the terms are `z`, by forward differences
        `eps` (k,)."""
        k = len(eps)
        return np.stack([(self._terms(metrics, delta + eps[j] * np.eye(k)[j]) - z) / eps[j] for j in range(k)], axis=2)

    def _terms(self, metrics: Metrics, delta: np.ndarray) -> np.ndarray:
        return np.nan_to_num(self.terms(self.shift(metrics, delta)), nan=0.0)
