"""Fit effects' parameters to minimise the gap measure D: a screen on a surrogate, then true refinements.

Every evaluation is a simulation and a calibration, so the search is small and batched: `search_effects`
runs one `EffectSearch` per effect in lock-step and hands all their points of a stage to one `evaluate`
call (one batched calibration for every effect's points). Per effect, with P = 1 or 2 fitted parameters:

1. Screen: `NODES[P]` evaluated nodes over the plausible range [low, high] (5, or 5 x 5). Every per-eye
   condition value is interpolated between the nodes (a cubic spline through 5 nodes; a tensor-product
   Lagrange quartic through 5 x 5), and D of the interpolated conditions is minimised on a dense grid (`DENSE[P]`
   points per parameter): the surrogate optimum, without further simulations (the conditions are smooth
   in the parameters: averages over fixations of smooth functions of the features).
2. The `TOP` effects of lowest screened score (D + 2k at the surrogate optimum or the best node) go on
   (`continue_search`): their surrogate optimum is evaluated, then `REFINE` refinements evaluate the
   neighbours of the best point so far at h = step/4, step/8, step/16 (2 or 8 points each, clipped to the
   range). Walk: where the finest refinement or a zoom's (3.) moves the best point (to the edge of its own
   window), it is repeated at the same h around the new best, up to `WALK` times per search, so that the
   quadratic below interpolates between points on both sides of the best instead of extrapolating from one side
   (a sharp, lopsided valley: a camera pose's yaw, whose one-sided parabola overshot by 0.08 deg, D 165 -> 218).
   When the refined effect of lowest score ends at an edge of its range (below: it will not be added), the next
   `TOP` screened effects are refined too (`EXTRA_WAVES` such waves at most): the screen's surrogate can underrate
   an effect (a tilted cornea screened at D 59 refined to 15, where the decentred pupil ranked first ends at an
   edge: gaze-error tables, blind single trial 18).
3. A quadratic D(u) = c + g.u + u.H.u / 2 (u in units of the last h = step/16) fitted by least squares to
   the evaluated points within h of the best (2h or 4h if too few: at a bound); if H is positive definite
   its minimum (kept within that window and the range) is evaluated; the best evaluated point is the
   estimate. The curvature gives a 1-sigma uncertainty sqrt(diag(2 H_theta^-1)) (Delta D = 1, D read as
   a chi-square); NaN if the parabola is not convex or its minimum is on a bound.
   Sandwich (`EffectSearch.correct`, `sandwich_factor`): reading D as a chi-square with one degree of freedom per
   term takes its terms as independent with unit variance. They are not: conditions share subjects and eyes (a
   scatter raises the error of all six Blignaut configurations together), so Delta D = 1 overstates what the
   data pin down. The reported sigma is the curvature's times the sandwich factor sqrt(diag(V) / diag((J'J)^-1)),
   V = (J'J)^-1 J' C J (J'J)^-1, J the terms' slope at the best point (a linear fit over the points within h),
   C their covariance over bootstrap resamples of eyes and subjects (`stats.term_covariance`): the M-estimator's
   sandwich variance relative to the chi-square reading's. Both read D near its minimum only. Where the valley of D
   is long and curved, or the parameters act on some eyes only (glint occlusion's radius sets which eyes a glint
   reaches, a share that differs between two samples of eyes), the estimate moves between samples far more than
   the curvature says. So the reported sigma is the larger of that and the spread of the minimum over resamples
   (`EffectSearch.correct`, `stats.resampled_gap_measure`): D of the screen's surrogate (1.) on its dense grid,
   near its least D (within `SPREAD_WINDOW`), under each of the same bootstrap resamples of eyes and subjects; the
   SD of where each resample's minimum lands. It is read only where the surrogate resolves the fitted minimum (its
   least D within `SURROGATE_AGREE` of the fit's; a well narrower than the nodes is left to the curvature). The
   search itself (zooms below) uses the curvature's sigma, so the fits and outcomes do not depend on either.
   Zoom: where that sigma is below h / `ZOOM_RATIO` (a parameter the data pin down far more finely than the
   last step, so D rises by more than `ZOOM_RATIO`^2 within one step and a parabola over the step misplaces
   the minimum), the refinement and the quadratic are repeated with h = max(2 sigma, h / 8) for that
   parameter, up to `ZOOM` times (a 1-sigma miss of a sharp parameter costs Delta D = 1, which the show eyes'
   tests can see).
4. Alternatives: nodes more than 1.5 node steps away whose D is within 1 of the best (e.g. the mirror sign
   of an effect that only error magnitudes see): the data cannot tell them apart.

An effect that is screened out keeps its best node (or the surrogate optimum's D, marked `screened`) and
no uncertainty; it ranks below every refined effect of equal score only by its (higher) D.

Ranking (`EffectFit.score`): D at the estimate plus 2 per fitted parameter (AIC-like, D read as -2 log
likelihood up to a constant). An effect is worth adding only if it lowers D by more than the point of
chi-square(k) at the given level (`EffectFit.passes`; the workflow's is Bonferroni over a round's candidates),
after dividing by the squared scale factor s^2 = max(1, D / (n - k)) (n terms of D): when the model with the
effect still misfits far beyond sampling, D's scale is inflated and so is every drop of D (the scale factor of
least squares with an unknown variance; the Particle Data Group's practice); and only if no fitted parameter
ends within `EDGE` (a fraction of its range) of a bound of its plausible range (`EffectFit.at_edge`): a fit
that wants to leave the plausible range is evidence against the effect, not a measurement of it. The reported
1-sigma uncertainties (the sandwich's, 3.) are multiplied by s; `EffectFit.ci95` is 1.96 of them.
`EffectFit.gof_p` is the goodness of fit of the model with the effect: P(chi-square(n - k) >= D).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats as sps

from eyehil.emulator.effects import Applied, Effect

NODES = {1: 5, 2: 5}  # 5 x 5 for two parameters: a 3 x 3 screen started a screen tilt in a second basin
DENSE = {1: 65, 2: 25}
REFINE = (2, 3, 4)  # refinement steps h = step / 2**r
ZOOM, ZOOM_RATIO = 2, 4.0  # zoomed refinements at most, and when (module docstring, 3.)
WALK = 2  # refinements repeated at the same h at most, while the best moves (module docstring, 2.)
TOP = 3
EXTRA_WAVES = 1  # waves of `TOP` more refinements when the refined best ends at an edge (module docstring, 2.)
EDGE = 0.01
SPREAD_WINDOW = 30.0  # surrogate points within this of its least D: where a resample's minimum may land
SURROGATE_AGREE = 2.0  # the surrogate's least D within this of the fit's: its minimum's spread is read

Metrics = dict[str, np.ndarray]
#: the gap measure D of P simulations at once: conditions shaped (P, E) -> (P,)
Score = Callable[[Metrics], np.ndarray]
#: the signed terms of D of P simulations (`stats.gap_terms`): conditions shaped (P, E) -> (P, T)
Terms = Callable[[Metrics], np.ndarray]
#: the covariance (T, T) of the terms of one simulation over resampled units (`stats.term_covariance`)
Covariance = Callable[[Metrics], np.ndarray]
#: D (B, P) of P simulations under each of B resamples of units (`stats.resampled_gap_measure`)
Resample = Callable[[Metrics], np.ndarray]


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
    screened: bool = False  # only screened (surrogate), not refined

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

    @property
    def off(self) -> bool:
        """Whether the fit does nothing: every fitted parameter whose neutral value lies in its range (those that
        can switch the effect off) is within `EDGE` of it."""
        can = [p for p in self.effect.fitted if p.switches_off]
        return bool(can) and all(abs(self.values[p.name] - p.neutral) <= EDGE * (p.high - p.low) for p in can)

    def basins(self) -> list[EffectFit]:
        """The screen's other basins: nodes of its grid (`NODES`) whose D is below every neighbour's (the 3^P - 1
        around) and below D0, more than 1.5 node steps from the fit, best first, each as a fit at its node (no
        sigma). A fit made beside another effect's
        open gap can land in the wrong one (a screen tilt's sign; `refit.restart`)."""
        params = self.effect.fitted
        n, P = NODES[len(params)], len(params)
        if len(self.Ds) < n**P:
            return []
        D = self.Ds[:n**P].reshape((n,) * P)
        padded = np.pad(D, 1, constant_values=np.inf)
        lowest = np.ones(D.shape, bool)
        for shift in itertools.product((-1, 0, 1), repeat=P):
            if any(shift):
                window = tuple(slice(1 + s, 1 + s + n) for s in shift)
                lowest &= padded[window] > D
        lo, hi = np.array([p.low for p in params]), np.array([p.high for p in params])
        step = (hi - lo) / (n - 1)
        at = np.array([self.values[p.name] for p in params])
        out = []
        for index in sorted(zip(*np.nonzero(lowest & (D < self.D0)), strict=True), key=lambda i: D[i]):
            node = lo + np.array(index) * step
            if np.any(np.abs(node - at) > 1.5 * step):
                values = {**self.values, **{p.name: float(v) for p, v in zip(params, node, strict=True)}}
                out.append(replace(self, values=values, D=float(D[index]), sigma=dict.fromkeys(self.sigma, np.nan),
                                   alternatives=[]))
        return out

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
    """One effect's search as a state machine: `ask()` the next points (None when done), `tell(D, metrics)`."""

    def __init__(self, effect: Effect, D0: float, n_conditions: int):
        self.effect, self.D0, self.n_conditions = effect, D0, n_conditions
        params = effect.fitted
        self.lo, self.hi = np.array([p.low for p in params]), np.array([p.high for p in params])
        n = NODES[len(params)]
        self.step = (self.hi - self.lo) / (n - 1)
        self.axes = [np.linspace(a, b, n) for a, b in zip(self.lo, self.hi, strict=True)]
        self.coarse = np.array(list(itertools.product(*self.axes)))
        self.points, self.Ds = np.empty((0, len(params))), np.empty(0)
        self.stage, self.sigma = 0, np.full(len(params), np.nan)
        self._plan: list[tuple[str, np.ndarray]] = []  # refinements and quadratics still to run, with their h
        self._h, self.zooms, self.walks = self.step / 2 ** REFINE[-1], 0, 0
        self._walk: tuple[np.ndarray, np.ndarray] | None = None  # the best and h of the refinement in flight
        self.surrogate: tuple[np.ndarray, float] | None = None
        self.metrics: list[Metrics] = []  # of every evaluated point, in the order of `points`
        self.factor = np.ones(len(params))  # `correct`: the sandwich's factor on the Delta D = 1 sigma
        self.spread = np.full(len(params), np.nan)  # `correct`: the surrogate minimum's bootstrap SD
        self._grid_D: np.ndarray | None = None  # the surrogate's D on its dense grid
        self._pending: np.ndarray | None = self.coarse
        self.screened = False

    @property
    def best(self) -> np.ndarray:
        return self.points[np.argmin(self.Ds)]

    @property
    def screen_score(self) -> float:
        """D + 2k at the better of the best node and the surrogate optimum."""
        d = float(np.min(self.Ds))
        if self.surrogate is not None:
            d = min(d, self.surrogate[1])
        return d + 2 * len(self.effect.fitted)

    def ask(self) -> np.ndarray | None:
        return self._pending

    def tell(self, Ds: np.ndarray, metrics: Sequence[Metrics] | None = None, score: Score | None = None) -> None:
        self.points = np.vstack([self.points, self._pending])
        self.Ds = np.concatenate([self.Ds, np.asarray(Ds, float)])
        if metrics is not None:
            self.metrics += list(metrics)
        self._pending = None
        if self.stage == 0:
            if metrics is not None and score is not None:
                u, Ds = surrogate_grid(self.axes, list(metrics), score, DENSE[len(self.lo)])
                self.surrogate, self._grid_D = grid_minimum(u, Ds), Ds
            self.screened = True  # waits for `continue_search`
            return
        self._advance()

    def continue_search(self) -> None:
        """Leave the screen: evaluate the surrogate optimum, then refine."""
        self.screened = False
        self.stage = 1
        self._plan = [*(("refine", self.step / 2 ** r) for r in REFINE), ("quadratic", self._h)]
        start = self.surrogate[0] if self.surrogate is not None else self.best
        self._pending = self._new(np.clip(start, self.lo, self.hi)[None])
        if self._pending is None:
            self._advance()

    def _advance(self) -> None:
        """The next task of the plan (refinements, then the quadratic's minimum), then zooms while they pay."""
        while self._pending is None:
            if self._walk is not None:
                centre, h = self._walk
                self._walk = None
                if self.walks < WALK and not np.allclose(self.best, centre, rtol=0, atol=1e-12):
                    self.walks += 1
                    self._plan.insert(0, ("refine", h))
            if not self._plan:
                h = self._zoom()
                if h is None:
                    return
                self.zooms += 1
                self._plan = [("refine", h), ("quadratic", h)]
            task, h = self._plan.pop(0)
            if task == "refine" and np.all(h <= self.step / 2 ** REFINE[-1] * (1 + 1e-9)):  # the finest and zooms
                self._walk = (self.best.copy(), h)
            self._pending = self._refinement(h) if task == "refine" else self._quadratic(h)

    def _zoom(self) -> np.ndarray | None:
        """The next zoom's h (module docstring, 3.), or None: no zoom left or none needed."""
        sharp = np.isfinite(self.sigma) & (self.sigma < self._h / ZOOM_RATIO)
        if self.zooms >= ZOOM or not sharp.any():
            return None
        return np.where(sharp, np.maximum(2.0 * np.nan_to_num(self.sigma), self._h / 8), self._h)

    def _refinement(self, h: np.ndarray) -> np.ndarray | None:
        offsets = np.array(list(itertools.product((-1.0, 0.0, 1.0), repeat=len(h))))
        return self._new(np.clip(self.best + offsets * h, self.lo, self.hi))

    def _new(self, cand: np.ndarray) -> np.ndarray | None:
        cand = np.unique(cand, axis=0)
        new = [c for c in cand if not np.any(np.all(np.isclose(self.points, c, atol=1e-12), axis=1))]
        return np.array(new) if new else None

    def _quadratic(self, h: np.ndarray) -> np.ndarray | None:
        estimate, sigma = quadratic_minimum(self.points, self.Ds, self.best, h, self.lo, self.hi)
        if estimate is None and self.zooms:
            return None  # a zoom's parabola failed: the coarser one's sigma stands
        self.sigma, self._h = sigma, h
        return None if estimate is None else self._new(estimate[None])

    def correct(self, terms: Terms, covariance: Covariance, resample: Resample | None = None) -> None:
        """The sandwich factor of the uncertainty (module docstring, 3.): the terms' gradient at the best point
        from a linear fit over the evaluated points within h of it (2h, 4h while too few), their covariance there
        by bootstrap; and with `resample`, the spread of the surrogate's minimum over the same resamples."""
        if self.stage <= 0 or not np.all(np.isfinite(self.sigma)) or len(self.metrics) != len(self.points):
            return
        if resample is not None and self._grid_D is not None:
            u, inter = interpolated(self.axes, self.metrics[:len(self.coarse)], DENSE[len(self.lo)])
            near = (self._grid_D <= np.nanmin(self._grid_D) + SPREAD_WINDOW).ravel()
            Ds = resample({k: v[near] for k, v in inter.items()})
            ok = np.isfinite(Ds).any(axis=1)
            if ok.sum() > 1:
                grid = np.array(list(itertools.product(*u)))[near]
                self.spread = np.std(grid[np.nanargmin(Ds[ok], axis=1)], axis=0, ddof=1)
        i = int(np.argmin(self.Ds))
        found = _window(self.points, self.points[i], self._h, lambda u: np.column_stack([np.ones(len(u)), u]),
                        spare=1)
        if found is None:
            return
        near, u, _, _ = found
        Z = terms(stacked([self.metrics[j] for j in np.flatnonzero(near)]))
        self.factor = sandwich_factor(u, Z, covariance(self.metrics[i]))

    def _spread(self, D: float) -> np.ndarray:
        """The surrogate minimum's bootstrap SD (`correct`) where the surrogate resolves the fitted minimum (its
        least D within `SURROGATE_AGREE` of the fit's) and the parabola gave a sigma; NaN elsewhere (module
        docstring, 3.)."""
        if self.surrogate is None or abs(self.surrogate[1] - D) > SURROGATE_AGREE:
            return np.full(len(self.sigma), np.nan)
        return np.where(np.isnan(self.sigma), np.nan, self.spread)

    def result(self) -> EffectFit:
        i = int(np.argmin(self.Ds))
        fitted = self.effect.fitted
        point, D = self.points[i], float(self.Ds[i])
        if self.screened and self.surrogate is not None and self.surrogate[1] < D:
            point, D = self.surrogate
        values = self.effect.values({p.name: float(v) for p, v in zip(fitted, point, strict=True)})
        n = len(self.coarse)
        far = np.any(np.abs(self.coarse - point) > 1.5 * self.step, axis=1) & (self.Ds[:n] < D + 1)
        alternatives = [{p.name: float(v) for p, v in zip(fitted, c, strict=True)} for c in self.coarse[far]]
        dof = self.n_conditions - len(fitted)
        scale = np.sqrt(max(1.0, D / dof)) if dof > 0 else 1.0
        sigma = np.full(len(fitted), np.nan) if self.screened else np.fmax(self.sigma * self.factor, self._spread(D))
        return EffectFit(self.effect, values, {p.name: float(s * scale) for p, s in zip(fitted, sigma, strict=True)},
                         float(D), float(self.D0), self.n_conditions, self.points, self.Ds, alternatives,
                         self.screened)


def sandwich_factor(u: np.ndarray, Z: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """sqrt(diag(V) / diag((J'J)^-1)) per parameter, V = (J'J)^-1 J' cov J (J'J)^-1: the sandwich variance of the
    minimum of D = |z|^2 against the chi-square reading's, which takes the terms z as independent with unit
    variance (cov = I: factor 1; a term counted twice, with its copy correlated 1: factor sqrt 2). J (T, P) is
    the slope of a linear fit of the terms `Z` (N, T) over the points' offsets `u` (N, P); ones where J'J is
    singular or the factor is not finite."""
    design = np.column_stack([np.ones(len(u)), u])
    J = np.linalg.lstsq(design, Z, rcond=None)[0][1:].T
    A = J.T @ J
    P = A.shape[0]
    if np.linalg.matrix_rank(A) < P:
        return np.ones(P)
    Ainv = np.linalg.inv(A)
    V = Ainv @ J.T @ cov @ J @ Ainv
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.sqrt(np.diag(V) / np.diag(Ainv))
    return np.where(np.isfinite(factor) & (factor > 0), factor, 1.0)


def surrogate_grid(axes: list[np.ndarray], metrics: list[Metrics], score: Score,
                   dense: int) -> tuple[list[np.ndarray], np.ndarray]:
    """score(interpolated conditions) on a dense grid over the nodes' range: (the grid's axes, D shaped (dense,) *
    P); the whole grid is scored in one call."""
    u, inter = interpolated(axes, metrics, dense)
    return u, np.asarray(score(inter), float).reshape((dense,) * len(axes))


def interpolated(axes: list[np.ndarray], metrics: list[Metrics], dense: int) -> tuple[list[np.ndarray], Metrics]:
    """Every per-eye condition interpolated from the nodes (`axes`, their `metrics` in the order of
    itertools.product) to a dense grid: (the grid's axes, conditions (dense ** P, E) in the grid's C order)."""
    values = stacked(metrics)  # (nodes, E)
    u = [np.linspace(a[0], a[-1], dense) for a in axes]
    if len(axes) == 1:
        from scipy.interpolate import make_interp_spline

        x = axes[0]
        return u, {k: make_interp_spline(x, _filled(v), k=min(3, len(x) - 1), axis=0)(u[0])
                   for k, v in values.items()}
    weights = [_lagrange(a, g) for a, g in zip(axes, u, strict=True)]  # (dense, nodes) each
    w = np.einsum("ai,bj->abij", *weights).reshape(dense * dense, -1)  # node order of itertools.product
    return u, {k: w @ _filled(v) for k, v in values.items()}


def grid_minimum(u: list[np.ndarray], Ds: np.ndarray) -> tuple[np.ndarray, float]:
    """The least D of a grid (`surrogate_grid`'s axes `u` and D, NaN ignored): (point, D)."""
    j = np.unravel_index(int(np.nanargmin(Ds)), Ds.shape)
    return np.array([a[i] for a, i in zip(u, j, strict=True)]), float(Ds[j])


def stacked(metrics: Sequence[Metrics]) -> Metrics:
    """Conditions of several simulations, each (E,), as one (P, E) array per condition."""
    return {k: np.array([m[k] for m in metrics], float) for k in metrics[0]}


def _filled(v: np.ndarray) -> np.ndarray:
    """NaN (an eye a node could not simulate or calibrate) replaced by the mean of the finite values; a condition
    with none (a Blignaut model that fails for every eye) by 0, which no measured condition refers to."""
    finite = np.isfinite(v)
    return np.where(finite, v, np.mean(v[finite]) if finite.any() else 0.0)


def _lagrange(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Lagrange basis weights (len(x), len(nodes)) of the polynomial through `nodes`."""
    out = np.ones((len(x), len(nodes)))
    for i, xi in enumerate(nodes):
        for j, xj in enumerate(nodes):
            if i != j:
                out[:, i] *= (x - xj) / (xi - xj)
    return out


def _window(points: np.ndarray, best: np.ndarray, h: np.ndarray, design: Callable[[np.ndarray], np.ndarray],
            spare: int = 0) -> tuple[np.ndarray, np.ndarray, float, np.ndarray] | None:
    """The evaluated points within h of `best` (widened to 2h, 4h while too few): (mask, offsets u in units of h,
    width, design(u)) for the first width where `design(u)` has full column rank with at least `spare` more rows
    than columns; None if none has."""
    for width in (1.0, 2.0, 4.0):
        u = (points - best) / h
        near = np.all(np.abs(u) <= width + 1e-9, axis=1)
        X = design(u[near])
        if near.sum() >= X.shape[1] + spare and np.linalg.matrix_rank(X) == X.shape[1]:
            return near, u[near], width, X
    return None


def quadratic_minimum(points, Ds, best, h, lo, hi) -> tuple[np.ndarray | None, np.ndarray]:
    """Minimum of a quadratic fitted to the points within h of `best` (widened to 2h, 4h while too few
    for the fit), and its 1-sigma (Delta D = 1); (None, NaN) if not convex."""
    P = len(best)
    pairs = [(a, b) for a in range(P) for b in range(a, P)]
    found = _window(points, best, h,
                    lambda u: np.column_stack([np.ones(len(u)), u, *[u[:, a] * u[:, b] for a, b in pairs]]))
    if found is None:
        return None, np.full(P, np.nan)
    near, _, width, design = found
    coef = np.linalg.lstsq(design, Ds[near], rcond=None)[0]
    g, H = coef[1:P + 1], np.zeros((P, P))
    for (a, b), c in zip(pairs, coef[P + 1:], strict=True):
        H[a, b] = H[b, a] = 2 * c if a == b else c
    if np.any(np.linalg.eigvalsh(H) <= 0):
        return None, np.full(P, np.nan)
    estimate = np.clip(best + np.clip(-np.linalg.solve(H, g), -width, width) * h, lo, hi)
    sigma = np.sqrt(np.diag(2.0 * np.linalg.inv(H) * np.outer(h, h)))
    on_bound = np.isclose(estimate, lo) | np.isclose(estimate, hi)
    return estimate, np.where(on_bound, np.nan, sigma)


def _best_at_edge(searches: Sequence[EffectSearch]) -> bool:
    """Whether the refined fit of lowest score ends at an edge of its range (`EffectFit.at_edge`)."""
    refined = [s.result() for s in searches if s.stage > 0]
    return bool(refined) and bool(min(refined, key=lambda f: f.score).at_edge)


def max_evaluations(effect: Effect, refined: bool = True) -> int:
    """Evaluations of one effect's search at most: nodes, and if refined the surrogate optimum, the
    refinements and their walks, the quadratic's minimum and the zooms."""
    P = len(effect.fitted)
    return NODES[P] ** P + (1 + (len(REFINE) + ZOOM + WALK) * (3**P - 1) + 1 + ZOOM if refined else 0)


def search_effects(effects: Sequence[Effect], evaluate: Callable[[list[Applied]], list[Metrics]],
                   score: Score, D0: float, n_conditions: int, top: int = TOP,
                   progress: Callable[[int], None] | None = None,
                   sandwich: tuple[Terms, Covariance, Resample | None] | None = None) -> list[EffectFit]:
    """Fit every effect (module docstring); `evaluate(applied list)` returns the conditions of each applied
    effect (one batch per stage), `score(conditions)` the D of each (conditions of P simulations, each (P, E), ->
    (P,): a batch's nodes and a surrogate grid are scored in one call); `progress(n)` after each batch;
    `sandwich` (the terms of D, their covariance, and D under resampled units or None: the curvature's and
    the sandwich's sigma alone) corrects the refined fits' uncertainties (`EffectSearch.correct`)."""
    searches = [EffectSearch(e, D0, n_conditions) for e in effects]
    waves = 0  # of refinements after the first (module docstring, 2.)
    while True:
        asks = [(s, s.ask()) for s in searches if s.ask() is not None]
        if not asks:
            waiting = [s for s in searches if s.screened and s.stage == 0]
            reserve = [s for s in searches if s.screened and s.stage == -1]
            if waiting:
                for s in waiting:
                    s.stage = -1  # screened out: done, unless refined below or in a later wave
            elif reserve and waves < EXTRA_WAVES and _best_at_edge(searches):
                waves += 1
            else:
                break
            for s in sorted(waiting or reserve, key=lambda s: s.screen_score)[:top]:
                s.continue_search()
            continue
        batch = [Applied.of(s.effect, dict(zip((p.name for p in s.effect.fitted), map(float, row), strict=True)))
                 for s, pts in asks for row in pts]
        metrics = evaluate(batch)
        if progress is not None:
            progress(len(batch))
        start = 0
        for s, pts in asks:
            part = metrics[start:start + len(pts)]
            s.tell(score(stacked(part)), part, score)
            start += len(pts)
    if sandwich is not None:
        for s in searches:
            s.correct(*sandwich)
    return [s.result() for s in searches]
