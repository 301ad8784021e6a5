"""Image-feature noise: what a real detector adds to the pupil and glint centres the host receives.

Frame: image pixels (OpenCV convention). Every valid pupil-ellipse centre and glint centre of every
fixation gets independent zero-mean Gaussian noise of standard deviation `sigma_px` in x and in y:

    u' = u + sigma_px * z,   z ~ N(0, 1) drawn from the caller's numpy Generator.

One fixation's feature in the emulator stands for the average over that fixation's frames, so `sigma_px`
is the noise of that average (the per-frame detector noise divided by sqrt(frames) when frames are
independent), not of single frames. The pupil boundary points are left as they are (the host's estimators
use only the centres). With the same Generator seed, the draws are identical for every `sigma_px`
(common random numbers), so a search over `sigma_px` sees a smooth objective.

Scale: with the Guestrin 2006 camera (f = 4667 px at 615 mm, 0.13 mm per px at the eye) a pupil-centre
error of 0.1 px moves the reconstructed optic axis by about 0.13 * 0.1 / 4.2 rad = 0.18 deg, so fractions
of a pixel matter. Reference: feature noise is the "precision" of Holmqvist, Nystrom & Mulvey 2012
(Eye tracker data quality: what it is and how to measure it, ETRA'12, 45-52); Guestrin & Eizenman 2006
(IEEE TBME 53(6)) discuss the estimator's sensitivity to it.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter, with_arrays
from eyehil.emulator.features import Features


class FeatureNoise(Effect):
    """Gaussian noise on the pupil and glint centres (px, per fixation)."""

    name = "feature_noise"
    stage = "features"
    reference = "Holmqvist, Nystrom & Mulvey 2012, ETRA'12 45-52"
    prior = "0.02-0.2 px per fixation average for a good remote tracker (0.1-0.5 px per frame)"
    parameters = (
        Parameter("sigma_px", "px", 0.0, 0.0, 0.4, neutral=0.0,
                  doc="SD of the noise of each centre coordinate, per fixation"),
    )

    def perturb(self, features: Features, values: Mapping[str, float],
                rng: np.random.Generator | None, **kwargs: object) -> Features:
        sigma = float(values["sigma_px"])
        if sigma < 0:
            raise ValueError(f"feature_noise: sigma_px must be >= 0, got {sigma}")
        if rng is None:
            raise ValueError("feature_noise needs a numpy Generator (rng)")
        pupil = features.pupil_centre_px + sigma * rng.standard_normal(features.pupil_centre_px.shape)
        glints = features.glint_px + sigma * rng.standard_normal(features.glint_px.shape)
        return with_arrays(features, pupil_centre_px=pupil, glint_px=glints)
