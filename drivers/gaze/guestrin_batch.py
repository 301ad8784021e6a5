"""Guestrin & Eizenman 2006 calibrated for many eyes at once: one vectorised Levenberg-Marquardt.

`calibrate_many(geometry, samples, targets, options=...)` fits (R, K, alpha, beta) of N eyes, each on
its own samples (N, T) at targets (T, 2) or (N, T, 2) screen mm, and returns a `BatchCalibration`
whose `estimate` and `errors_deg` map samples (N, ...) of the same eyes. It minimises exactly what
`guestrin.GuestrinEstimator` minimises with scipy's `least_squares` for one eye (the same residuals
of `GuestrinOptions.objective`, the same bounds and start), and reaches the same minimum: the
Jacobian is the same forward difference (relative step 1e-5 of max(1, |x|), stepping back inside a
bound, as scipy's `diff_step=1e-5`), so both stop where that Jacobian's gradient J^T r vanishes
(tests/test_gaze_batch.py: equal to 1e-6 deg on the published eyes).

Iteration, per eye and vectorised over the eyes still active: step d from (A + lambda diag(A)) d = -g,
A = J^T W J and g = J^T W r (W = 1 for least squares; for the sum of errors, the iteratively reweighted
model W = e'(d)/d of `_Problem.weights`, whose g is that objective's exact gradient), with the
parameters held whose bound blocks the gradient, clipped into the bounds; accepted
if it lowers that eye's cost (lambda / 3) and refused otherwise (lambda * 4). An eye stops when an
accepted step changes its parameters by less than 1e-11 (relative) or its cost by less than 1e-15
(relative), or lambda exceeds 1e10. The corneal centre depends on R only; the glint rays and their
common direction (`cornea.glint_rays`) and the pupil rays are computed once per calibration.

Eyes whose calibration is impossible (fewer than 2 valid targets, or no reconstruction at the start
for some valid sample) get NaN parameters and a reason in `BatchCalibration.reasons`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from eyehil.drivers.gaze.base import STUDY_VIEWING_DISTANCE_MM, EyeSamples
from eyehil.drivers.gaze.cornea import corneal_distance, glint_rays, refracted_pupil_centre
from eyehil.drivers.gaze.geometry import TrackerGeometry
from eyehil.drivers.gaze.guestrin import (
    BOUNDS,
    PROFILES,
    EyeParameters,
    GuestrinOptions,
    gaze_error_deg,
    gaze_plane,
    point_of_gaze,
    visual_axis,
)

NAMES = ("R", "K", "alpha_deg", "beta_deg")
_MISSING = 1e3  # residual of a valid sample whose eye cannot be reconstructed, as in the estimator
_DIFF_STEP = 1e-5


def start_parameters(eye: Literal["right", "left"] = "right") -> np.ndarray:
    """The published start (R 7.8 mm, K 4.2 mm, alpha +5 deg right / -5 deg left, beta 1.5 deg)."""
    s = EyeParameters.start(eye)
    return np.array([s.R, s.K, s.alpha_deg, s.beta_deg])


@dataclass(frozen=True, eq=False)
class _Rays:
    """What the residuals need from N eyes' samples (N, T): rays and masks, computed once."""

    e_glints: np.ndarray  # (N, T, L, 3)
    b: np.ndarray  # (N, T, 3)
    e_pupil: np.ndarray  # (N, T, 3)
    valid: np.ndarray  # (N, T)

    @classmethod
    def of(cls, geometry: TrackerGeometry, samples: EyeSamples) -> _Rays:
        stand_in = geometry.camera.K[:2, 2]  # finite features for invalid samples (masked later)
        glints = np.where(samples.valid[..., None, None], samples.glints_px, stand_in)
        pupil = np.where(samples.valid[..., None], samples.pupil_px, stand_in)
        e, b = glint_rays(geometry.camera, geometry.leds, glints)
        return cls(e, b, geometry.camera.ray_directions(pupil), samples.valid)

    def take(self, index: np.ndarray) -> _Rays:
        return _Rays(self.e_glints[index], self.b[index], self.e_pupil[index], self.valid[index])


class _Problem:
    """Residuals (N, M) of the options' objective for parameters x (N, 4) of the eyes in `rays`."""

    def __init__(self, geometry: TrackerGeometry, options: GuestrinOptions, targets: np.ndarray) -> None:
        self.geometry, self.options, self.targets = geometry, options, targets
        self.plane = gaze_plane(geometry, options.gaze_plane_offset_mm)

    def centres(self, rays: _Rays, x: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
        """Corneal centres (N, T, 3) for radii x[:, 0]; `near` (N, T, 3): the centres at a nearby R (a start)."""
        o = self.geometry.camera.o
        start = None if near is None else np.sum((near - o) * rays.b, axis=-1)
        k = corneal_distance(o, self.geometry.leds, rays.e_glints, rays.b, x[:, :1], self.options.corneal_distance,
                             start)
        return o + k[..., None] * rays.b

    def residuals(self, rays: _Rays, x: np.ndarray, c: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """(N, M) residuals given the corneal centres c; 0 for invalid samples, `_MISSING` where unreconstructable.

        On-screen mm (x, y per target) for the "screen" and "sum-of-errors" objectives, chords for "angular"."""
        o, opt = self.geometry.camera.o, self.options
        p = refracted_pupil_centre(o, rays.e_pupil, c, x[:, :1], x[:, 1:2], opt.n1)
        w = (p - c) / np.linalg.norm(p - c, axis=-1, keepdims=True)
        nu = visual_axis(w, x[:, 2:3], x[:, 3:4], opt.visual_axis)
        if opt.objective == "angular":
            to_target = self.geometry.screen.to_world(targets) - c
            r = to_target / np.linalg.norm(to_target, axis=-1, keepdims=True) - nu
        else:
            r = self.plane.intersect(c, nu) - targets
        r = np.where(rays.valid[..., None], np.where(np.isfinite(r), r, _MISSING), 0.0)
        return r.reshape(len(x), -1)

    def _errors(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-target errors e (N, T) deg of on-screen residuals r (N, 2T), and the distances d (mm)."""
        delta = r.reshape(len(r), -1, 2)
        d = np.sqrt(np.sum(delta**2, axis=-1) + (self.options.gaze_plane_offset_mm**2 if self.options.error_metric
                                                  == "3-d" else 0.0))
        return np.degrees(np.arctan(d / STUDY_VIEWING_DISTANCE_MM)), d

    def cost(self, r: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """(N,) objective: 0.5 sum r^2 (least squares) or the sum of the valid targets' errors (deg)."""
        if self.options.objective != "sum-of-errors":
            return 0.5 * np.sum(r**2, axis=1)
        return np.sum(np.where(valid, self._errors(r)[0], 0.0), axis=1)

    def weights(self, r: np.ndarray) -> np.ndarray | float:
        """Weights W (N, M) making g = J^T W r the objective's gradient; J^T W J is the step's model Hessian.

        1 for least squares. For the sum of errors e(d) = atan(d / 650 mm), d = sqrt(|r_t|^2 + offset^2):
        W = e'(d) / d per target (deg / mm^2), the iteratively reweighted least-squares model of sum e."""
        if self.options.objective != "sum-of-errors":
            return 1.0
        _, d = self._errors(r)
        de_dd = np.degrees(1.0 / STUDY_VIEWING_DISTANCE_MM) / (1.0 + (d / STUDY_VIEWING_DISTANCE_MM) ** 2)
        return np.repeat(de_dd / np.maximum(d, 1e-12), 2, axis=1)


@dataclass(frozen=True, eq=False)
class BatchCalibration:
    """N calibrated eyes: `params` (N, 4) R (mm), K (mm), alpha, beta (deg), NaN for failed eyes.

    `cost` (N,) = the objective (0.5 sum of squared residuals, or the sum of errors in deg); `iterations`
    (N,); `reasons` maps a failed eye's index to why; `options` are the estimator's (`guestrin.GuestrinOptions`).
    """

    geometry: TrackerGeometry
    options: GuestrinOptions
    params: np.ndarray
    cost: np.ndarray
    iterations: np.ndarray
    reasons: Mapping[int, str]

    @property
    def ok(self) -> np.ndarray:
        """(N,) True where the eye was calibrated."""
        return np.all(np.isfinite(self.params), axis=1)

    def parameters(self, extra_dims: int) -> EyeParameters:
        """The parameters as an `EyeParameters` of arrays (N, 1 x extra_dims) (failed eyes: the start)."""
        x = np.where(self.ok[:, None], self.params, start_parameters())
        pad = (slice(None),) + (None,) * extra_dims
        return EyeParameters(*(x[:, i][pad] for i in range(4)), n1=self.options.n1)

    def estimate(self, samples: EyeSamples) -> np.ndarray:
        """Points of gaze (N, ..., 2) screen mm of samples (N, ...) of the same eyes; NaN for failed eyes."""
        extra = len(samples.shape) - 1
        g = point_of_gaze(self.geometry, samples, self.parameters(extra), options=self.options)
        return np.where(self.ok[(slice(None),) + (None,) * (extra + 1)], g, np.nan)

    def errors_deg(self, samples: EyeSamples, targets_mm: np.ndarray) -> np.ndarray:
        """Errors (N, ...) deg in the options' metric of samples (N, ...) at targets broadcasting to (N, ..., 2)."""
        return gaze_error_deg(self.estimate(samples), targets_mm, self.options)


def calibrate_many(
    geometry: TrackerGeometry,
    samples: EyeSamples,
    targets_mm: np.ndarray,
    *,
    options: GuestrinOptions | str | None = None,
    eye: Literal["right", "left"] = "right",
    start: np.ndarray | None = None,
    bounds: Mapping[str, tuple[float, float]] = BOUNDS,
    max_iter: int = 200,
    xtol: float = 1e-11,
    ftol: float = 1e-15,
) -> BatchCalibration:
    """Calibrate N eyes from samples (N, T) fixating targets (T, 2) or (N, T, 2) screen mm.

    `options`: a `GuestrinOptions` or a profile name (default "best"). `start` (N, 4) or (4,) defaults
    to the published start for `eye`. Two LEDs or more (the one-LED form needs the eye distance). An eye
    stops when a step changes no parameter by more than `xtol` relative (absolute below 1), when an accepted
    step lowers the cost by no more than `ftol` relative, or when the damping exceeds 1e10; the defaults are
    tight enough that the study's results equal the per-eye estimators' to 1e-6 deg.
    """
    if isinstance(options, str) or options is None:
        options = PROFILES[options or "best"]
    if geometry.n_leds < 2:
        raise ValueError("calibrate_many needs two or more LEDs (the one-LED form needs the eye distance)")
    if samples.n_leds != geometry.n_leds:
        raise ValueError(f"samples carry {samples.n_leds} glints, the geometry has {geometry.n_leds} LEDs")
    if len(samples.shape) != 2:
        raise ValueError(f"samples must have batch shape (N eyes, T targets), got {samples.shape}")
    n, t = samples.shape
    targets = np.broadcast_to(np.asarray(targets_mm, float), (n, t, 2))
    if not np.all(np.isfinite(targets)):
        raise ValueError("targets_mm must be finite")
    lo, hi = np.array([bounds[k] for k in NAMES]).T
    x0 = start_parameters(eye) if start is None else np.asarray(start, float)
    x = np.clip(np.broadcast_to(x0, (n, 4)).astype(float), lo, hi)
    x = np.where(np.isfinite(x), x, start_parameters(eye))
    problem, rays = _Problem(geometry, options, targets), _Rays.of(geometry, samples)
    c = problem.centres(rays, x)
    r = problem.residuals(rays, x, c, targets)
    reasons: dict[int, str] = {}
    n_valid = samples.valid.sum(axis=1)
    for i in np.flatnonzero(2 * n_valid < 4):
        reasons[int(i)] = f"{n_valid[i]} valid targets for 4 parameters"
    for i in np.flatnonzero(np.any(np.abs(r) >= _MISSING, axis=1)):
        reasons.setdefault(int(i), "no eye reconstruction at the start parameters for some samples")
    active = np.ones(n, bool)
    active[list(reasons)] = False
    cost, lam, iterations = problem.cost(r, samples.valid), np.full(n, 1e-3), np.zeros(n, int)
    for _ in range(max_iter):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        sub = rays.take(a)
        xn, cn_, rn = _lm_step(problem, sub, targets[a], x[a], c[a], r[a], lam[a], lo, hi)
        cn = problem.cost(rn, sub.valid)
        better = cn < cost[a]
        small_step = np.all(np.abs(xn - x[a]) <= xtol * np.maximum(np.abs(x[a]), 1.0), axis=1)
        small_gain = (cost[a] - cn) <= ftol * cost[a]
        x[a] = np.where(better[:, None], xn, x[a])
        c[a] = np.where(better[:, None, None], cn_, c[a])
        r[a] = np.where(better[:, None], rn, r[a])
        cost[a] = np.where(better, cn, cost[a])
        lam[a] = np.where(better, lam[a] / 3, lam[a] * 4)
        iterations[a] += 1
        active[a[small_step | (better & small_gain) | (lam[a] > 1e10)]] = False
    for i in np.flatnonzero(np.any(np.abs(r) >= _MISSING, axis=1)):
        reasons.setdefault(int(i), "some valid samples cannot be reconstructed at the fitted parameters")
    failed = np.zeros(n, bool)
    failed[list(reasons)] = True
    params = np.where(failed[:, None], np.nan, x)
    return BatchCalibration(geometry, options, params, np.where(failed, np.nan, cost), iterations, reasons)


def _jacobian(problem: _Problem, rays: _Rays, targets, x, c, r, lo, hi) -> np.ndarray:
    """Forward-difference Jacobian (N, M, 4), steps as scipy's least_squares with diff_step=1e-5."""
    h = _DIFF_STEP * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
    h = np.where((x + h > hi) | (x + h < lo), -h, h)  # step back inside a bound
    J = np.empty((*r.shape, x.shape[1]))
    for j in range(x.shape[1]):
        xp = x.copy()
        xp[:, j] += h[:, j]
        dx = xp[:, j] - x[:, j]
        cp = problem.centres(rays, xp, c) if j == 0 else c
        J[..., j] = (problem.residuals(rays, xp, cp, targets) - r) / dx[:, None]
    return J


def _lm_step(problem: _Problem, rays: _Rays, targets, x, c, r, lam, lo, hi):
    """One damped Gauss-Newton trial step for every eye: (new x, its corneal centres, its residuals)."""
    J = _jacobian(problem, rays, targets, x, c, r, lo, hi)
    W = problem.weights(r)
    A = np.einsum("nri,nrj->nij", J * np.asarray(W)[..., None] if np.ndim(W) else J, J)
    g = np.einsum("nri,nr->ni", J, W * r)
    held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))  # a bound blocks the descent direction
    free = ~held
    A = A * (free[:, :, None] & free[:, None, :]) + np.eye(x.shape[1]) * held[:, :, None]
    g = np.where(held, 0.0, g)
    diag = np.einsum("nii->ni", A)
    damped = A + (lam[:, None] * diag)[:, :, None] * np.eye(x.shape[1])
    step = -np.linalg.solve(damped + 1e-30 * np.eye(x.shape[1]), g[..., None])[..., 0]
    xn = np.clip(x + step, lo, hi)
    cn = problem.centres(rays, xn, c)
    return xn, cn, problem.residuals(rays, xn, cn, targets)
