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

from dataclasses import dataclass

import numpy as np

from eyehil.analysis.study.bridge import binocular_samples, eye_samples, screen_targets, tracker_geometry
from eyehil.analysis.study.published import CONFIGURATIONS, calibration_sets
from eyehil.drivers.gaze.base import BinocularSamples, EyeSamples, angular_error_deg, on_screen_error_deg
from eyehil.drivers.gaze.blignaut import BlignautEstimator
from eyehil.drivers.gaze.forms import MODELS
from eyehil.drivers.gaze.guestrin import GuestrinEstimator
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene


@dataclass(frozen=True)
class GuestrinResult:
    """Per eye: H1, H2 (deg), the fitted parameters (R, K, alpha, beta) and failure reasons ("" if none)."""

    h1: np.ndarray
    h2: np.ndarray
    params: np.ndarray  # (E, 4)
    failures: list[str]


def guestrin(features: Features, scene: Scene, *, n1: float = 1.3375, side: str = "right") -> GuestrinResult:
    """Run the Guestrin experiment on features shaped (E, S, H=5, T=9); head position 0 is central."""
    geometry = tracker_geometry(scene)
    samples = eye_samples(features, side)
    targets = screen_targets(scene)
    estimator = GuestrinEstimator(geometry, eye=side, n1=n1)
    n = samples.shape[0]
    h1, h2, params, failures = np.full(n, np.nan), np.full(n, np.nan), np.full((n, 4), np.nan), []
    for i in range(n):
        central = EyeSamples(samples.pupil_px[i, 0], samples.glints_px[i, 0], samples.valid[i, 0])
        fit = estimator.calibrate(central, targets)
        if not fit:
            failures.append(f"eye {i}: {fit.reason}")
            continue
        every = EyeSamples(samples.pupil_px[i], samples.glints_px[i], samples.valid[i])
        err = on_screen_error_deg(fit.estimate(every), np.broadcast_to(targets, (samples.shape[1], *targets.shape)))
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


def _one(samples: BinocularSamples, i: int) -> BinocularSamples:
    pick = (i, 0)
    return BinocularSamples(*(EyeSamples(e.pupil_px[pick], e.glints_px[pick], e.valid[pick])
                              for e in (samples.right, samples.left)))


def _subset(samples: BinocularSamples, index: np.ndarray) -> BinocularSamples:
    return BinocularSamples(*(EyeSamples(e.pupil_px[index], e.glints_px[index], e.valid[index])
                              for e in (samples.right, samples.left)))
