"""A glint on the pupil's edge hides part of it, and the detected pupil centre moves away from the glint.

Frame: image pixels. The pupil's edge is the forward model's fitted pupil ellipse (`pupil_centre_px`,
`pupil_axes_px`, `pupil_angle_deg`; it matches the ray-traced boundary to about 1e-6 px), sampled at
`EDGE_SAMPLES` points evenly spaced in its parameter, whose mean is the pupil centre: the effect does not
depend on how many boundary points were ray-traced. A point of the edge within `radius_px` of any glint is
hidden by the glint's bright disc; a detector that estimates the centre from the visible boundary (a
centroid, or an ellipse fit without robust outlier handling pulled by the gap) moves it by

    delta = bias x (mean of the visible points - mean of all points),

`bias` = 1 for a centroid of the visible edge, 0 for a detector that fits an ellipse robustly through the
gap (Swirski, Bulling & Dodgson 2012, ETRA'12 173-176; Santini, Fuhl & Kasneci 2018, CVIU 170:40-50:
occlusion by glints is the commonest failure of pupil detection). The shift is zero unless a glint is on
the edge, so it acts at some targets and head positions only, in the direction away from the glint.

Both parameters are fitted. A glint's bright disc (its radius in the image: LED power, exposure, the
threshold of the detector) is as unknown for a real tracker as the detector's bias, and the radius sets the
share of eyes and fixations whose glint meets the pupil's edge: with the radius fixed, a sample of model eyes
with fewer such eyes than the measured ones can only match the data with a bias beyond 1 (Blignaut 2014: 31 %
of 16 model eyes against 45-80 % in 20-eye Rozema draws, docs/blind-trials.md, 19th session). The radius's
`neutral` is 0 (a disc of no size hides nothing), outside its plausible range: the effect is switched off by
its bias.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter, with_arrays
from eyehil.emulator.features import Features

#: points of the pupil's edge (the fitted ellipse) tested against the glints: 3 deg apart
EDGE_SAMPLES = 120


class GlintOcclusion(Effect):
    """The pupil centre pulled away from a glint that hides part of the pupil's edge (bias 0..1, glint radius)."""

    name = "glint_occlusion"
    stage = "features"
    reference = "Swirski, Bulling & Dodgson 2012, ETRA'12 173-176; Santini, Fuhl & Kasneci 2018, CVIU 170:40-50"
    prior = ("bias 0 for robust ellipse fitting, up to 1 for centroid detectors; radius a few px, set by LED power, "
             "exposure and the detector's threshold (no published spread)")
    parameters = (
        Parameter("bias", "", 0.0, 0.0, 1.0, neutral=0.0, doc="fraction of the visible-edge centroid's shift"),
        Parameter("radius_px", "px", 4.0, 1.0, 10.0, neutral=0.0, doc="radius of a glint's bright disc"),
    )

    def perturb(self, features: Features, values: Mapping[str, float], rng: np.random.Generator | None,
                **kwargs: object) -> Features:
        bias, radius = float(values["bias"]), float(values["radius_px"])
        points = edge_points(features)
        ok = np.broadcast_to(features.pupil_valid[..., None], points.shape[:-1])
        gl = np.where(features.glint_valid[..., None], features.glint_px, np.inf)
        dist = np.linalg.norm(points[..., :, None, :] - gl[..., None, :, :], axis=-1)  # (..., N, L)
        visible = ok & np.all(dist > radius, axis=-1)
        n_all, n_vis = np.sum(ok, axis=-1), np.sum(visible, axis=-1)
        p = np.nan_to_num(points)
        mean_all = np.sum(np.where(ok[..., None], p, 0.0), axis=-2) / np.maximum(n_all, 1)[..., None]
        mean_vis = np.sum(np.where(visible[..., None], p, 0.0), axis=-2) / np.maximum(n_vis, 1)[..., None]
        shift = np.where(((n_vis > 2) & (n_vis < n_all))[..., None], mean_vis - mean_all, 0.0)
        return with_arrays(features, pupil_centre_px=features.pupil_centre_px + bias * shift)


def edge_points(features: Features) -> np.ndarray:
    """The fitted pupil ellipse sampled at EDGE_SAMPLES points, (..., EDGE_SAMPLES, 2) px (NaN where no pupil)."""
    t = np.linspace(0.0, 2.0 * np.pi, EDGE_SAMPLES, endpoint=False)
    phi = np.radians(features.pupil_angle_deg)[..., None]
    a, b = features.pupil_axes_px[..., 0, None] / 2.0, features.pupil_axes_px[..., 1, None] / 2.0
    u, v = a * np.cos(t), b * np.sin(t)
    x = features.pupil_centre_px[..., 0, None] + u * np.cos(phi) - v * np.sin(phi)
    y = features.pupil_centre_px[..., 1, None] + u * np.sin(phi) + v * np.cos(phi)
    return np.stack([x, y], axis=-1)
