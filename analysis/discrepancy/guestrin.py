"""The Guestrin 2006 experiment batched over eyes: one calibration solve for a whole batch, per-eye metrics.

`calibrate_batch` fits the same personal calibration as `eyehil.drivers.gaze.guestrin.GuestrinEstimator`
(R, K, alpha, beta; on-screen residuals in mm over the central-position targets; the same bounds and
start) for N eyes at once, by a Levenberg-Marquardt iteration vectorised over eyes: per eye, forward-
difference Jacobian J (2T x 4; relative step 1e-5, as the estimator's diff_step: the inner corneal-centre
solve is too noisy for smaller steps), step (J^T J + lambda diag(J^T J)) d = -J^T r, kept
inside the bounds by clipping, accepted if it lowers that eye's cost (lambda / 5) and refused otherwise
(lambda * 5); an eye stops when an accepted step lowers its cost by less than `tol` (relative) or lambda
exceeds 1e6. Each residual evaluation reconstructs the gaze of all active eyes together with the host's
own functions (`eyehil.drivers.gaze.cornea`, `eyehil.drivers.gaze.guestrin.visual_axis`), and the corneal centres are
solved only when R changes (2 of the 5 evaluations of an iteration); this makes a parameter search
affordable (about 20x faster than one `least_squares` per eye). H1 and H2 agree with
`eyehil.analysis.study.experiments.guestrin` to about 5e-5 deg (tests/test_discrepancy.py).

`guestrin_metrics` turns calibrated estimates into per-eye conditions (degrees): "H1" (central position),
"H2" (the moved positions), "head:<name>" (one head position), and the signed mean errors
"bias_x:H1|H2", "bias_y:H1|H2" (screen x = world +x, the subject's left; y up; atan(mm / 650 mm)).
"""

from __future__ import annotations

import warnings

import numpy as np

from eyehil.analysis.study.bridge import eye_samples, screen_targets, tracker_geometry
from eyehil.drivers.gaze.base import STUDY_VIEWING_DISTANCE_MM, EyeSamples, on_screen_error_deg
from eyehil.drivers.gaze.cornea import corneal_centre, pupil_centre
from eyehil.drivers.gaze.geometry import TrackerGeometry
from eyehil.drivers.gaze.guestrin import BOUNDS, EyeParameters, point_of_gaze, visual_axis
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene

NAMES = ("R", "K", "alpha_deg", "beta_deg")
START = np.array([7.8, 4.2, 5.0, 1.5])  # the published start (right eye)
N1 = 1.3375  # corneal index of the estimator (the study's text)
_MISSING = 1e3  # residual (mm) of a valid sample whose eye cannot be reconstructed, as in the estimator


def _params(x: np.ndarray, extra_dims: int) -> EyeParameters:
    pad = (slice(None),) + (None,) * extra_dims
    return EyeParameters(*(x[:, i][pad] for i in range(len(NAMES))))


def _centre(geometry: TrackerGeometry, samples: EyeSamples, x: np.ndarray) -> np.ndarray:
    """Corneal centres (N, T, 3) for radii x[:, 0] (the only parameter they depend on)."""
    stand_in = geometry.camera.K[:2, 2]  # finite glints for invalid samples, masked later (as `reconstruct`)
    glints = np.where(samples.valid[..., None, None], samples.glints_px, stand_in)
    return corneal_centre(geometry.camera, geometry.leds, glints, x[:, 0, None])


def _residuals(geometry: TrackerGeometry, samples: EyeSamples, targets: np.ndarray, x: np.ndarray,
               c: np.ndarray) -> np.ndarray:
    """(N, 2T) on-screen residuals (mm) given corneal centres c; 0 for invalid samples, `_MISSING` where the
    eye cannot be reconstructed. The gaze of `eyehil.drivers.gaze.guestrin.point_of_gaze`, two LEDs or more."""
    pupil = np.where(samples.valid[..., None], samples.pupil_px, geometry.camera.K[:2, 2])
    p = pupil_centre(geometry.camera, pupil, c, x[:, 0, None], x[:, 1, None], N1)
    nu = visual_axis((p - c) / np.linalg.norm(p - c, axis=-1, keepdims=True), x[:, 2, None], x[:, 3, None])
    r = geometry.screen.intersect(c, nu) - targets
    r = np.where(samples.valid[..., None], np.where(np.isfinite(r), r, _MISSING), 0.0)
    return r.reshape(len(x), -1)


def calibrate_batch(geometry: TrackerGeometry, samples: EyeSamples, targets: np.ndarray, *,
                    start: np.ndarray | None = None, max_iter: int = 100, tol: float = 1e-8) -> np.ndarray:
    """Calibrated (R, K, alpha, beta) (N, 4) of N eyes from samples (N, T) at targets (T, 2) screen mm.

    `start` (N, 4) defaults to the published start (7.8 mm, 4.2 mm, +5 deg, 1.5 deg: right eyes). Rows are
    NaN where a calibration is impossible (fewer than 2 valid targets, or eyes not reconstructable).
    """
    if geometry.n_leds < 2:
        raise ValueError("calibrate_batch needs two or more LEDs (the one-LED form needs the eye distance)")
    n = samples.shape[0]
    lo, hi = np.array([BOUNDS[k] for k in NAMES]).T
    x = np.clip(np.tile(START, (n, 1)) if start is None else np.array(start, float), lo, hi)
    x = np.where(np.isfinite(x), x, START)
    c = _centre(geometry, samples, x)
    r = _residuals(geometry, samples, targets, x, c)
    cost, lam, active = np.sum(r**2, axis=1), np.full(n, 1e-2), np.ones(n, bool)
    for _ in range(max_iter):
        a = np.flatnonzero(active)
        if a.size == 0:
            break
        sub = EyeSamples(samples.pupil_px[a], samples.glints_px[a], samples.valid[a])
        xn, cn_, rn = _lm_step(geometry, sub, targets, x[a], c[a], r[a], lam[a], lo, hi)
        cn = np.sum(rn**2, axis=1)
        better = cn < cost[a]
        gain = (cost[a] - cn) / np.maximum(cost[a], 1e-300)
        x[a] = np.where(better[:, None], xn, x[a])
        c[a] = np.where(better[:, None, None], cn_, c[a])
        r[a] = np.where(better[:, None], rn, r[a])
        cost[a] = np.where(better, cn, cost[a])
        lam[a] = np.where(better, lam[a] / 5, lam[a] * 5)
        active[a[(better & (gain < tol)) | (lam[a] > 1e6)]] = False
    failed = (np.sum(samples.valid, axis=1) < 2) | np.any(np.abs(r) >= _MISSING, axis=1)
    return np.where(failed[:, None], np.nan, x)


def _lm_step(geometry, samples, targets, x, c, r, lam, lo, hi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One damped Gauss-Newton trial step for every eye: (new x, its corneal centres, its residuals).

    Forward differences; only the R column needs new corneal centres."""
    h = 1e-5 * np.maximum(np.abs(x), 1.0)
    J = np.empty((*r.shape, x.shape[1]))
    for j in range(x.shape[1]):
        xp = x.copy()
        xp[:, j] += h[:, j]
        cp = _centre(geometry, samples, xp) if j == 0 else c
        J[..., j] = (_residuals(geometry, samples, targets, xp, cp) - r) / h[:, j, None]
    A = np.einsum("nri,nrj->nij", J, J)
    g = np.einsum("nri,nr->ni", J, r)
    damped = A + lam[:, None, None] * np.einsum("nii->ni", A)[:, :, None] * np.eye(x.shape[1])
    step = -np.linalg.solve(damped + 1e-12 * np.eye(x.shape[1]), g[..., None])[..., 0]
    xn = np.clip(x + step, lo, hi)
    cn = _centre(geometry, samples, xn)
    return xn, cn, _residuals(geometry, samples, targets, xn, cn)


def guestrin_metrics(features: Features, host: Scene, *, start: np.ndarray | None = None,
                     side: str = "right") -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per-eye conditions (deg, each (E,)) and calibrated parameters (E, 4) of features (E, S, H, T).

    `host` is the scene the host believes (nominal camera, LEDs, screen); head position 0 is central.
    """
    geometry, targets = tracker_geometry(host), screen_targets(host)
    s = eye_samples(features, side)
    central = EyeSamples(s.pupil_px[:, 0], s.glints_px[:, 0], s.valid[:, 0])
    params = calibrate_batch(geometry, central, targets, start=start)
    ok = np.all(np.isfinite(params), axis=1)
    estimate = point_of_gaze(geometry, s, _params(np.where(ok[:, None], params, START), 2))
    estimate = np.where(ok[:, None, None, None], estimate, np.nan)
    error = on_screen_error_deg(estimate, targets)
    signed = np.degrees(np.arctan((estimate - targets) / STUDY_VIEWING_DISTANCE_MM))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: eyes that could not be calibrated
        out = {"H1": np.nanmean(error[:, 0], axis=-1), "H2": np.nanmean(error[:, 1:], axis=(1, 2))}
        for h, head in enumerate(features.head_positions[1:], start=1):
            out[f"head:{getattr(head, 'name', h)}"] = np.nanmean(error[:, h], axis=-1)
        for key, part in (("H1", signed[:, :1]), ("H2", signed[:, 1:])):
            out[f"bias_x:{key}"] = np.nanmean(part[..., 0], axis=(1, 2))
            out[f"bias_y:{key}"] = np.nanmean(part[..., 1], axis=(1, 2))
    return out, params

