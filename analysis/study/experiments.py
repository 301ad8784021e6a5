"""The two replicated experiments, per eye (pure: features in, errors out).

Guestrin & Eizenman 2006: calibrate (R, K, alpha, beta) of each eye on the 9 targets at the central
head position; H1 = mean error over those 9, H2 = mean over the 36 fixations at the four moved head
positions; error = atan(on-screen distance / 650 mm) as in the published study.

Blignaut 2014: for every model 1-8 and calibration configuration (C5 ... C135), fit on the
configuration's targets and score the binocular average on all 135 targets; error = angle between
the directions from the cyclopean eye (the head-frame origin) to the estimate and to the target.
Fits with fewer targets than terms fail explicitly (NaN): the published real-world table lists such
cells (e.g. model 3 at C5), computed by a solver we do not reproduce.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from eyehil.analysis.study.bridge import binocular_samples, eye_samples, screen_targets, tracker_geometry
from eyehil.analysis.study.published import CONFIGURATIONS, calibration_sets
from eyehil.drivers.gaze.base import BinocularSamples, EyeSamples, angular_error_deg
from eyehil.drivers.gaze.blignaut import BlignautEstimator, fit_form_many, normalised_pupil_glint
from eyehil.drivers.gaze.forms import MODELS, design_matrix
from eyehil.drivers.gaze.guestrin import GuestrinEstimator, GuestrinOptions
from eyehil.drivers.gaze.guestrin_batch import calibrate_many
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene


@dataclass(frozen=True)
class GuestrinResult:
    """Per eye: H1, H2 (deg), the fitted parameters (R, K, alpha, beta) and failure reasons ("" if none)."""

    h1: np.ndarray
    h2: np.ndarray
    params: np.ndarray  # (E, 4)
    failures: list[str]


def guestrin_batched(features: Features, scene: Scene, options: GuestrinOptions, *, side: str = "right"
                     ) -> GuestrinResult:
    """The Guestrin experiment for all eyes at once (`eyehil.drivers.gaze.guestrin_batch`), errors in the options'
    metric; features shaped (E, S, H, T=9), head position 0 central; H2 = mean over the other positions."""
    geometry = tracker_geometry(scene)
    samples = eye_samples(features, side)
    targets = screen_targets(scene)
    central = EyeSamples(samples.pupil_px[:, 0], samples.glints_px[:, 0], samples.valid[:, 0])
    fit = calibrate_many(geometry, central, targets, options=options, eye=side)
    err = fit.errors_deg(samples, targets)
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: eyes that could not be calibrated
        h1, h2 = np.nanmean(err[:, 0], axis=-1), np.nanmean(err[:, 1:], axis=(1, 2))
    failures = [f"eye {i}: {why}" for i, why in sorted(fit.reasons.items())]
    return GuestrinResult(h1, h2, fit.params, failures)


def guestrin(features: Features, scene: Scene, *, n1: float = 1.3375, side: str = "right",
             options: GuestrinOptions | None = None) -> GuestrinResult:
    """Run the Guestrin experiment eye by eye with the per-eye estimator (scipy), the reference of
    `guestrin_batched`; features shaped (E, S, H, T=9); head position 0 is central."""
    geometry = tracker_geometry(scene)
    samples = eye_samples(features, side)
    targets = screen_targets(scene)
    estimator = GuestrinEstimator(geometry, eye=side, n1=n1, options=options)
    n = samples.shape[0]
    h1, h2, params, failures = np.full(n, np.nan), np.full(n, np.nan), np.full((n, 4), np.nan), []
    for i in range(n):
        central = EyeSamples(samples.pupil_px[i, 0], samples.glints_px[i, 0], samples.valid[i, 0])
        fit = estimator.calibrate(central, targets)
        if not fit:
            failures.append(f"eye {i}: {fit.reason}")
            continue
        every = EyeSamples(samples.pupil_px[i], samples.glints_px[i], samples.valid[i])
        err = fit.errors_deg(every, np.broadcast_to(targets, (samples.shape[1], *targets.shape)))
        h1[i], h2[i] = np.nanmean(err[0]), np.nanmean(err[1:])
        p = fit.parameters
        params[i] = (p.R, p.K, p.alpha_deg, p.beta_deg)
    return GuestrinResult(h1, h2, params, failures)


@dataclass(frozen=True)
class BlignautResult:
    """errors (E, 8 models, 6 configurations) in degrees, NaN where a fit was impossible; failure reasons."""

    errors: np.ndarray
    failures: dict[tuple[int, str], str]


def blignaut(features: Features, scene: Scene) -> BlignautResult:
    """Run the Blignaut experiment on binocular features shaped (E, 2, 1, 135)."""
    samples = binocular_samples(features)
    targets = screen_targets(scene)
    targets_world = scene.targets()
    sets = calibration_sets()
    n = samples.shape[0]
    errors = np.full((n, len(MODELS), len(CONFIGURATIONS)), np.nan)
    failures: dict[tuple[int, str], str] = {}
    for i in range(n):
        eye = _one(samples, i)
        for m, k in enumerate(sorted(MODELS)):
            estimator = BlignautEstimator.from_model(k)
            for c, name in enumerate(CONFIGURATIONS):
                subset = sets[name]
                fit = estimator.calibrate(_subset(eye, subset), targets[subset])
                if not fit:
                    failures.setdefault((k, name), fit.reason)
                    continue
                estimate = scene.screen.centre + np.column_stack([fit.estimate(eye), np.zeros(len(targets))])
                errors[i, m, c] = np.nanmean(angular_error_deg(np.zeros(3), estimate, targets_world))
    return BlignautResult(errors, failures)


def blignaut_batched(features: Features, scene: Scene) -> BlignautResult:
    """`blignaut` for all eyes at once: every (model, configuration) fit of every eye as one batched
    least squares per form and screen axis (`eyehil.drivers.gaze.blignaut.fit_form_many`)."""
    samples = binocular_samples(features)
    right, left = (f[:, 0] for f in normalised_pupil_glint(samples))  # (E, 135, 2)
    valid = samples.valid[:, 0]  # (E, 135): both eyes
    targets = screen_targets(scene)
    targets_world = scene.targets()
    n = len(valid)
    errors = np.full((n, len(MODELS), len(CONFIGURATIONS)), np.nan)
    failures: dict[tuple[int, str], str] = {}
    for c, (name, subset) in enumerate(calibration_sets().items()):
        used = valid[:, subset]
        for m, k in enumerate(sorted(MODELS)):
            estimator = BlignautEstimator.from_model(k)
            estimate = np.zeros((n, len(targets), 2))
            ok = np.ones(n, bool)
            for side, feats in (("right", right), ("left", left)):
                for axis, form in enumerate((estimator.x_form, estimator.y_form)):
                    values = np.broadcast_to(targets[subset, axis], used.shape)
                    coef, reasons = fit_form_many(form, feats[:, subset], values, used)
                    for why in reasons:
                        if why is not None:
                            failures.setdefault((k, name), f"{side} eye, screen {'xy'[axis]}: {why}")
                            break
                    ok &= np.array([why is None for why in reasons])
                    estimate[..., axis] += 0.5 * np.einsum("etm,em->et", design_matrix(form, feats), coef)
            estimate = np.where(valid[..., None], estimate, np.nan)
            world = scene.screen.centre + np.concatenate([estimate, np.zeros((n, len(targets), 1))], axis=-1)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(angular_error_deg(np.zeros(3), world, targets_world), axis=-1)
            errors[:, m, c] = np.where(ok, mean, np.nan)
    return BlignautResult(errors, failures)


def _one(samples: BinocularSamples, i: int) -> BinocularSamples:
    pick = (i, 0)
    return BinocularSamples(*(EyeSamples(e.pupil_px[pick], e.glints_px[pick], e.valid[pick])
                              for e in (samples.right, samples.left)))


def _subset(samples: BinocularSamples, index: np.ndarray) -> BinocularSamples:
    return BinocularSamples(*(EyeSamples(e.pupil_px[index], e.glints_px[index], e.valid[index])
                              for e in (samples.right, samples.left)))
