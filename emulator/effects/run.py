"""The forward model with effects: (eyes, scene, applied effects, rng) -> Features.

Sessions: head position 0 of the scene is the calibration session, the other head positions are the
validation session (the Guestrin 2006 protocol: calibrate at the central position, judge at the moved
ones; a one-position scene such as Blignaut 2014 has only a calibration session). Each session is ray-traced
with the eyes and scene that every effect's `apply` gives for it, in the order the effects are listed; the
sessions' features are joined along the head axis (E, S, H, T, ...) in the scene's head order; then every
effect's `perturb` acts on the features with the caller's Generator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from eyehil.emulator.effects.base import Applied
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene


def sessions(scene: Scene) -> list[tuple[str, tuple[HeadPose, ...]]]:
    """[("calibration", first head position), ("validation", the others)] (the second only if any)."""
    heads = tuple(scene.head_positions)
    out = [("calibration", heads[:1])]
    return [*out, ("validation", heads[1:])] if len(heads) > 1 else out


def simulate_with(eyes: EyeModel, scene: Scene, applied: Sequence[Applied] = (), *,
                  rng: np.random.Generator | None = None, **kwargs) -> Features:
    """Features of `eyes` in `scene` with `applied` effects; `kwargs` go to `eyehil.emulator.forward.simulate`."""
    parts = [simulate_session(eyes, scene, applied, session, heads, **kwargs) for session, heads in sessions(scene)]
    return perturb(join_heads(parts, scene), applied, rng)


def simulate_session(eyes: EyeModel, scene: Scene, applied: Sequence[Applied], session: str,
                     heads: tuple[HeadPose, ...], **kwargs) -> Features:
    """Ray-traced features (before `perturb`) of one session: its head positions, every effect's `apply`."""
    e, s = eyes.as_batch(), replace(scene, head_positions=heads)
    for a in applied:
        e, s = a.effect.apply(e, s, a.values, session)
    return simulate(e, s, head_positions=s.head_positions, **kwargs)


def perturb(features: Features, applied: Sequence[Applied], rng: np.random.Generator | None) -> Features:
    """Every effect's `perturb`, in order."""
    for a in applied:
        features = a.effect.perturb(features, a.values, rng)
    return features


def join_heads(parts: Sequence[Features], scene: Scene) -> Features:
    """Features of the same eyes and targets at different head positions, joined along the head axis."""
    if len(parts) == 1:
        return parts[0]
    arrays = {k: np.concatenate([p.arrays[k] for p in parts], axis=2) for k in parts[0].arrays}
    heads = tuple(h for p in parts for h in p.head_positions)
    return replace(parts[0], scene=scene.name, head_positions=heads, arrays=arrays)
