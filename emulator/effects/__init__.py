"""Optional model extensions, each named and parameterised: the vocabulary of the discrepancy workflow.

The table maps a name to "module:Class"; a module is imported only when its effect is asked for
(python-can's interface table). Every effect documents its physics, units, frame and a reference, and
is the identity at its parameters' neutral values (`eyehil.emulator.effects.base`).

| name            | stage    | fitted parameters            | acts on                                        |
|-----------------|----------|------------------------------|------------------------------------------------|
| feature_noise   | features | sigma_px (px)                | pupil and glint centres, every fixation        |
| pupil_decentre  | model    | nasal_mm, superior_mm (mm)   | the pupil centre, every fixation               |
| pupil_change    | model    | delta_diameter_mm (mm)       | pupil size and centre at the validation heads  |
| lens_distortion | model    | k1 (normalised)              | the simulated camera; the host stays pinhole   |
| head_roll       | model    | roll_deg (deg)               | head (eye) roll at the validation heads        |

    from eyehil.emulator.effects import Applied, get, simulate_with
    noise = get("feature_noise")
    features = simulate_with(eyes, scene, [Applied.of(noise, sigma_px=0.1)], rng=np.random.default_rng(1))
"""

from __future__ import annotations

import importlib

from eyehil.emulator.effects.base import SESSIONS, Applied, Effect, Parameter
from eyehil.emulator.effects.run import sessions, simulate_with

EFFECTS: dict[str, str] = {
    "feature_noise": "eyehil.emulator.effects.noise:FeatureNoise",
    "pupil_decentre": "eyehil.emulator.effects.pupil:PupilDecentre",
    "pupil_change": "eyehil.emulator.effects.pupil:PupilChange",
    "lens_distortion": "eyehil.emulator.effects.scene:LensDistortion",
    "head_roll": "eyehil.emulator.effects.scene:HeadRoll",
}


def names() -> list[str]:
    """The registered effect names, in table order."""
    return list(EFFECTS)


def get(name: str) -> Effect:
    """The effect registered as `name`; ValueError naming the known ones otherwise."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
    module, cls = EFFECTS[name].split(":")
    return getattr(importlib.import_module(module), cls)()


def parse(spec: str) -> Applied:
    """`NAME=V[,V...]` (the fitted parameters in order) or `NAME:PARAM=V[,PARAM=V...]` -> Applied."""
    name, colon, tail = spec.partition(":")
    try:
        if colon:
            effect = get(name.strip())
            given = dict(item.split("=", 1) for item in tail.split(","))
        else:
            name, _, tail = spec.partition("=")
            effect = get(name.strip())
            values = tail.split(",") if tail else []
            if len(values) != len(effect.fitted):
                raise ValueError(f"{effect.name} takes {len(effect.fitted)} value(s): "
                                 f"{', '.join(p.name for p in effect.fitted)}")
            given = {p.name: v for p, v in zip(effect.fitted, values, strict=True)}
        return Applied.of(effect, {k.strip(): float(v) for k, v in given.items()})
    except ValueError as exc:
        raise ValueError(f"effect spec {spec!r}: {exc} (use NAME=VALUE[,VALUE] or NAME:PARAM=VALUE,...)") from None


__all__ = ["EFFECTS", "SESSIONS", "Applied", "Effect", "Parameter", "get", "names", "parse", "sessions",
           "simulate_with"]
