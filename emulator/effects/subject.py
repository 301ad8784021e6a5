"""What the subject does that the protocol assumes away: fixations off the target, a head that moves.

Both effects are random per fixation and small, so they act on the features through the features'
first-order response to the displacement (`Effect.sensitivity`: finite differences of ray-traced features,
computed once per eye set and cached), not by ray tracing every draw:

    u' = u + sum_j (du / dd_j) d_j,   d ~ N(0, sigma^2 I), one draw per eye, head position and target.

u are the pupil-ellipse centre and glint centres (px). One fixation in the emulator stands for a
fixation's average, so d is the displacement of that average: head movement within a fixation averages
to its mean position to first order (the features are smooth in the head position), so "during" and
"between" fixations are the same parameter here; the per-frame spread is larger by sqrt(frames). With
the same Generator seed the draws are the same for every sigma (common random numbers).

## Fixation error (`FixationError`)

The eye looks at a point displaced from the target by d (angles; the displacement in the screen plane
is d x the screen's distance), the host labels the sample with the target. Reference: fixational
drift and microsaccades keep the line of sight within about 0.1-0.3 deg of a target, and the mean
fixation position of a naive subject misses small targets by 0.2-0.5 deg (Holmqvist et al. 2011, Eye
Tracking: A Comprehensive Guide, ch. 4; Nystrom, Andersson, Holmqvist & van de Weijer 2013, Behav Res
Methods 45:272-288).

## Head movement (`HeadJitter`)

The head is displaced by d (mm, isotropic in the scene frame's x, y, z) from the position the protocol
assumes for each fixation; the eye keeps fixating the target (the forward model's fixation). A chin rest
holds the head to about 1 mm; a free head drifts by 2-10 mm (Hessels, Cornelissen, Kemner & Hooge 2015,
Behav Res Methods 47:848-859; Niehorster, Cornelissen, Holmqvist, Hooge & Hessels 2018, Behav Res
Methods 50:213-227).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter, with_arrays
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene

KEYS = ("pupil_centre_px", "glint_px")
FIXATION_STEP_MM = 2.0
HEAD_STEP_MM = 1.0


def _media(scene: Scene):
    from eyehil.emulator.effects.run import media_of

    return media_of(scene)


def _difference(moved: Features, plain: Features, step: float) -> dict[str, np.ndarray]:
    return {k: (moved.arrays[k] - plain.arrays[k]) / step for k in KEYS}


def _stack(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per key: (..., n_directions) derivatives."""
    return {k: np.stack([p[k] for p in parts], axis=-1) for k in KEYS}


def _apply(features: Features, sensitivity: Mapping[str, np.ndarray], d: np.ndarray) -> Features:
    """u' = u + J d for d (E, S, H, T, n_directions)."""
    pupil = features.pupil_centre_px + np.nan_to_num(np.einsum("...cj,...j->...c", sensitivity["pupil_centre_px"], d))
    glints = features.glint_px + np.nan_to_num(np.einsum("...lcj,...j->...lc", sensitivity["glint_px"], d))
    return with_arrays(features, pupil_centre_px=pupil, glint_px=glints)


def _draw(features: Features, n: int, rng: np.random.Generator | None, who: str) -> np.ndarray:
    if rng is None:
        raise ValueError(f"{who} needs a numpy Generator (rng)")
    return rng.standard_normal((*features.shape, n))


class FixationError(Effect):
    """Each fixation lands off its target by a random angle (deg, SD per axis, per fixation)."""

    name = "fixation_error"
    stage = "features"
    needs_sensitivity = True
    reference = ("Holmqvist et al. 2011, Eye Tracking: A Comprehensive Guide (OUP), ch. 4; Nystrom et al. "
                 "2013, Behav Res Methods 45:272-288")
    prior = "0.1-0.5 deg SD of a fixation's mean position about the target"
    parameters = (
        Parameter("sigma_deg", "deg", 0.0, 0.0, 1.0, neutral=0.0, doc="SD per screen axis of the fixation's miss"),
    )

    def sensitivity(self, eyes: EyeModel, scene: Scene, session: str, heads: tuple) -> dict[str, np.ndarray]:
        """d(features)/d(target displacement, mm) along screen x and y (finite differences of 2 mm)."""
        targets = scene.targets()
        plain = simulate(eyes, scene, head_positions=heads, media=_media(scene), targets=targets)
        parts = []
        for axis in (0, 1):
            moved_targets = targets.copy()
            moved_targets[:, axis] += FIXATION_STEP_MM
            moved = simulate(eyes, scene, head_positions=heads, media=_media(scene), targets=moved_targets)
            parts.append(_difference(moved, plain, FIXATION_STEP_MM))
        return _stack(parts)

    def perturb(self, features: Features, values: Mapping[str, float], rng: np.random.Generator | None,
                **kwargs: object) -> Features:
        sigma = float(values["sigma_deg"])
        if sigma < 0:
            raise ValueError(f"fixation_error: sigma_deg must be >= 0, got {sigma}")
        distance = float(np.median(features.targets[:, 2])) if features.targets is not None else 650.0
        d = _draw(features, 2, rng, self.name) * distance * np.tan(np.radians(sigma))
        return _apply(features, kwargs["sensitivity"], d)  # type: ignore[arg-type]


class HeadJitter(Effect):
    """The head displaced from its protocol position at each fixation (mm, SD per axis, per fixation)."""

    name = "head_jitter"
    stage = "features"
    needs_sensitivity = True
    reference = ("Hessels et al. 2015, Behav Res Methods 47:848-859; Niehorster et al. 2018, Behav Res "
                 "Methods 50:213-227")
    prior = "about 1 mm with a chin rest, 2-10 mm with a free head"
    parameters = (
        Parameter("sigma_mm", "mm", 0.0, 0.0, 10.0, neutral=0.0, doc="SD per scene axis of the head's position"),
    )

    def sensitivity(self, eyes: EyeModel, scene: Scene, session: str, heads: tuple) -> dict[str, np.ndarray]:
        """d(features)/d(head translation, mm) along scene x, y, z (finite differences of 1 mm)."""
        plain = simulate(eyes, scene, head_positions=heads, media=_media(scene))
        parts = []
        for axis in range(3):
            moved_heads = tuple(_moved(h, axis, HEAD_STEP_MM) for h in heads)
            moved = simulate(eyes, scene, head_positions=moved_heads, media=_media(scene))
            parts.append(_difference(moved, plain, HEAD_STEP_MM))
        return _stack(parts)

    def perturb(self, features: Features, values: Mapping[str, float], rng: np.random.Generator | None,
                **kwargs: object) -> Features:
        sigma = float(values["sigma_mm"])
        if sigma < 0:
            raise ValueError(f"head_jitter: sigma_mm must be >= 0, got {sigma}")
        return _apply(features, kwargs["sensitivity"], sigma * _draw(features, 3, rng, self.name))  # type: ignore[arg-type]


def _moved(head: HeadPose, axis: int, step: float) -> HeadPose:
    name = ("x", "y", "z")[axis]
    return replace(head, **{name: getattr(head, name) + step})
