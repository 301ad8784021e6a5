"""Received samples as the arrays the gaze estimators take (`eyehil.drivers.gaze.base.EyeSamples`).

A sample is usable for one eye when its pupil is DETECTED (and not BLINK) and every glint carried is
VALID. Image coordinates are full-sensor pixels (OpenCV convention), as on the wire.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from eyehil.drivers.gaze.base import BinocularSamples, EyeSamples
from eyehil.drivers.wire import Sample
from eyehil.protocols.enums import Eye, GlintFlags, PupilFlags


def eye_arrays(samples: Sequence[Sample], eye: Eye, n_leds: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pupil centres (N, 2), glints (N, L, 2) px and usable (N,) of one eye; NaN where not usable.

    L = `n_leds`, by default the glint count of the samples (constant within a stream); samples without
    that eye or with another glint count are unusable.
    """
    n = len(samples)
    if n_leds is None:
        n_leds = max((len(e.glints) for s in samples for e in s.eyes if e.eye == eye), default=0)
    pupil, glints, usable = np.full((n, 2), np.nan), np.full((n, n_leds, 2), np.nan), np.zeros(n, bool)
    for i, s in enumerate(samples):
        e = s.eye(eye)
        if e is None or len(e.glints) != n_leds:
            continue
        ok = PupilFlags.DETECTED in e.flags and PupilFlags.BLINK not in e.flags
        ok = ok and all(GlintFlags.VALID in g.flags for g in e.glints)
        if ok:
            pupil[i] = e.centre_x, e.centre_y
            glints[i] = [(g.x, g.y) for g in e.glints]
            usable[i] = True
    return pupil, glints, usable


def eye_samples(samples: Sequence[Sample], eye: Eye, n_leds: int | None = None) -> EyeSamples:
    """`EyeSamples` (N,) of one eye."""
    return EyeSamples(*eye_arrays(samples, eye, n_leds))


def binocular_samples(samples: Sequence[Sample], n_leds: int | None = None) -> BinocularSamples:
    """`BinocularSamples` (N,) of both eyes."""
    return BinocularSamples(eye_samples(samples, Eye.RIGHT, n_leds), eye_samples(samples, Eye.LEFT, n_leds))


def fixation_mean(samples: Sequence[Sample], eye: Eye, n_leds: int, min_usable: float = 0.5) -> EyeSamples:
    """One fixation's features with `n_leds` glints: the mean over its usable samples, `EyeSamples` of shape ().

    Invalid if fewer than `min_usable` of the samples are usable.
    """
    pupil, glints, usable = eye_arrays(samples, eye, n_leds)
    if not len(samples) or usable.mean() < min_usable:
        return EyeSamples(np.full(2, np.nan), np.full((n_leds, 2), np.nan), np.array(False))
    return EyeSamples(pupil[usable].mean(0), glints[usable].mean(0), np.array(True))
