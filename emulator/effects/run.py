"""The forward model with effects: (eyes, scene, applied effects, rng) -> Features.

Sessions: head position 0 of the scene is the calibration session, the other head positions are the
validation session (the Guestrin 2006 protocol: calibrate at the central position, judge at the moved
ones; a one-position scene such as Blignaut 2014 has only a calibration session). Each session is ray-traced
with the eyes and scene that every effect's `apply` gives for it, in the order the effects are listed; the
sessions' features are joined along the head axis (E, S, H, T, ...) in the scene's head order; then every
effect's `perturb` acts on the features with the caller's Generator (and, for effects that set
`needs_sensitivity`, their `sensitivity` of the same sessions, joined the same way).

A scene's `extra["index_shift"]` (set by `eyehil.emulator.effects.cornea.CornealIndex`) adds to the corneal and
aqueous refractive indices of the scene's media for that session.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from eyehil.emulator.effects.base import Applied, Effect
from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene

Sensitivities = Mapping[str, dict[str, np.ndarray]]


def sessions(scene: Scene) -> list[tuple[str, tuple[HeadPose, ...]]]:
    """[("calibration", first head position), ("validation", the others)] (the second only if any)."""
    heads = tuple(scene.head_positions)
    out = [("calibration", heads[:1])]
    return [*out, ("validation", heads[1:])] if len(heads) > 1 else out


def simulate_with(eyes: EyeModel, scene: Scene, applied: Sequence[Applied] = (), *,
                  rng: np.random.Generator | None = None, **kwargs) -> Features:
    """Features of `eyes` in `scene` with `applied` effects; `kwargs` go to `eyehil.emulator.forward.simulate`."""
    parts = [simulate_session(eyes, scene, applied, session, heads, **kwargs) for session, heads in sessions(scene)]
    needed = {a.effect.name: a.effect for a in applied if a.effect.needs_sensitivity}
    base = [a for a in applied if not a.effect.needs_sensitivity]
    sens = {n: sensitivity(e, eyes, scene, base) for n, e in needed.items()}
    return perturb(join_heads(parts, scene), applied, rng, sens)


def session_model(eyes: EyeModel, scene: Scene, applied: Sequence[Applied], session: str,
                  heads: tuple[HeadPose, ...]) -> tuple[EyeModel, Scene]:
    """The eyes and scene of one session after every effect's `apply`."""
    e, s = eyes.as_batch(), replace(scene, head_positions=heads)
    for a in applied:
        e, s = a.effect.apply(e, s, a.values, session)
    return e, s


def media_of(scene: Scene) -> Media:
    """The scene's media with `extra["index_shift"]` added to the cornea and aqueous."""
    media = Media.named(scene.media, scene.wavelength_nm)
    shift = float(scene.extra.get("index_shift", 0.0))
    if shift == 0.0:
        return media
    return replace(media, cornea=media.cornea + shift, aqueous=media.aqueous + shift,
                   label=f"{media.label}{shift:+.4f}")


def simulate_session(eyes: EyeModel, scene: Scene, applied: Sequence[Applied], session: str,
                     heads: tuple[HeadPose, ...], **kwargs) -> Features:
    """Ray-traced features (before `perturb`) of one session: its head positions, every effect's `apply`."""
    e, s = session_model(eyes, scene, applied, session, heads)
    kwargs.setdefault("media", media_of(s))
    return simulate(e, s, head_positions=s.head_positions, **kwargs)


def sensitivity(effect: Effect, eyes: EyeModel, scene: Scene, base: Sequence[Applied]) -> dict[str, np.ndarray]:
    """`effect.sensitivity` of every session (with the `base` effects applied), joined along the head axis."""
    parts = []
    for session, heads in sessions(scene):
        e, s = session_model(eyes, scene, base, session, heads)
        parts.append(effect.sensitivity(e, s, session, s.head_positions))
    return {k: np.concatenate([p[k] for p in parts], axis=2) for k in parts[0]}


def perturb(features: Features, applied: Sequence[Applied], rng: np.random.Generator | None,
            sensitivities: Sensitivities | None = None) -> Features:
    """Every effect's `perturb`, in order."""
    for a in applied:
        if a.effect.needs_sensitivity:
            if sensitivities is None or a.effect.name not in sensitivities:
                raise ValueError(f"effect {a.effect.name!r} needs its sensitivity (effects.run.sensitivity)")
            features = a.effect.perturb(features, a.values, rng, sensitivity=sensitivities[a.effect.name])
        else:
            features = a.effect.perturb(features, a.values, rng)
    return features


def join_heads(parts: Sequence[Features], scene: Scene) -> Features:
    """Features of the same eyes and targets at different head positions, joined along the head axis."""
    if len(parts) == 1:
        return parts[0]
    arrays = {k: np.concatenate([p.arrays[k] for p in parts], axis=2) for k in parts[0].arrays}
    heads = tuple(h for p in parts for h in p.head_positions)
    return replace(parts[0], scene=scene.name, head_positions=heads, arrays=arrays)
