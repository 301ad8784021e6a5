"""The Guestrin 2006 experiment batched over eyes for the discrepancy workflow: per-eye metrics.

The calibration is `eyehil.drivers.gaze.guestrin_batch.calibrate_many` (one Levenberg-Marquardt vectorised over
eyes, the same implementation the study runs), here with the "best" profile (eyehil's own estimator: least
squares over both glints, on-screen residuals, n1 1.3375). `calibrate_batch` is kept as a thin wrapper for
existing callers; new code should call `calibrate_many` directly.

`guestrin_metrics` turns calibrated estimates into per-eye conditions (degrees): "H1" (central position),
"H2" (the moved positions), "head:<name>" (one head position), and the signed mean errors
"bias_x:H1|H2", "bias_y:H1|H2" (screen x = world +x, the subject's left; y up; atan(mm / 650 mm)).
"""

from __future__ import annotations

import warnings

import numpy as np

from eyehil.analysis.study.bridge import eye_samples, screen_targets, tracker_geometry
from eyehil.drivers.gaze.base import STUDY_VIEWING_DISTANCE_MM, EyeSamples, on_screen_error_deg
from eyehil.drivers.gaze.geometry import TrackerGeometry
from eyehil.drivers.gaze.guestrin_batch import NAMES, calibrate_many, start_parameters
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene

__all__ = ["NAMES", "START", "calibrate_batch", "guestrin_metrics"]

START = start_parameters("right")  # the published start (right eye)
#: the calibration's stopping tolerances in the workflow (`calibrate_many`'s xtol, ftol): looser than the
#: study's, they change the per-eye conditions by at most 2e-6 deg (measured on feature noise, pupil change and
#: lens distortion, 20 published eyes, warm-started) and save a third to a half of the iterations
XTOL, FTOL = 1e-7, 1e-10


def calibrate_batch(geometry: TrackerGeometry, samples: EyeSamples, targets: np.ndarray, *,
                    start: np.ndarray | None = None, max_iter: int = 200, tol: float | None = None) -> np.ndarray:
    """Calibrated (R, K, alpha, beta) (N, 4) of N eyes from samples (N, T) at targets (T, 2) screen mm.

    A thin wrapper of `calibrate_many` (profile "best"); rows are NaN where a calibration is impossible.
    `tol` is accepted for compatibility and ignored (the solver converges to its own tight tolerances).
    """
    if start is not None:
        start = np.where(np.isfinite(start), start, START)
    return calibrate_many(geometry, samples, targets, options="best", start=start, max_iter=max_iter).params


def guestrin_metrics(features: Features, host: Scene, *, start: np.ndarray | None = None,
                     side: str = "right") -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per-eye conditions (deg, each (E,)) and calibrated parameters (E, 4) of features (E, S, H, T).

    `host` is the scene the host believes (nominal camera, LEDs, screen); head position 0 is central.
    """
    geometry, targets = tracker_geometry(host), screen_targets(host)
    s = eye_samples(features, side)
    central = EyeSamples(s.pupil_px[:, 0], s.glints_px[:, 0], s.valid[:, 0])
    if start is not None:
        start = np.where(np.isfinite(start), start, START)
    fit = calibrate_many(geometry, central, targets, options="best", start=start, xtol=XTOL, ftol=FTOL)
    params = fit.params
    estimate = fit.estimate(s)
    return error_conditions(estimate, targets, features.head_positions), params


def error_conditions(estimate: np.ndarray, targets: np.ndarray, head_positions) -> dict[str, np.ndarray]:
    """Per-eye gaze-error conditions (deg) of estimates shaped (eyes, heads, targets, 2): H1 (central head),
    H2 (the others), head:<name>, and the signed biases bias_x / bias_y of H1 and H2."""
    error = on_screen_error_deg(estimate, targets)
    signed = np.degrees(np.arctan((estimate - targets) / STUDY_VIEWING_DISTANCE_MM))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: eyes that could not be calibrated
        out = {"H1": np.nanmean(error[:, 0], axis=-1), "H2": np.nanmean(error[:, 1:], axis=(1, 2))}
        for h, head in enumerate(head_positions[1:], start=1):
            out[f"head:{getattr(head, 'name', h)}"] = np.nanmean(error[:, h], axis=-1)
        for key, part in (("H1", signed[:, :1]), ("H2", signed[:, 1:])):
            out[f"bias_x:{key}"] = np.nanmean(part[..., 0], axis=(1, 2))
            out[f"bias_y:{key}"] = np.nanmean(part[..., 1], axis=(1, 2))
    return out
