"""Optional model extensions, each a documented class: the catalogue of the discrepancy workflow.

Modules (each effect is a subclass of `base.Effect` and registers itself by being defined):

- `base`: the `Effect` interface, `Parameter`, `Applied`, the registry `REGISTRY`.
- `run`: the forward model with effects (`simulate_with`), sessions, sensitivities.
- `noise`: feature_noise. `pupil`: pupil_decentre, pupil_change, pupil_shift. `cornea`:
  corneal_asphericity, corneal_index. `subject`: fixation_error, head_jitter. `scene`: lens_distortion,
  head_roll. `camera`: tangential_distortion, camera_pose, camera_bump. `geometry`: led_position,
  screen_position, screen_tilt. `occlusion`: glint_occlusion.
- `anatomy`: corneal_astigmatism, cornea_tilt, cornea_decentre, pupil_ellipse (the anatomy of
  `eyehil.emulator.eye.anatomy`).

| name                  | stage    | fitted parameters                  | acts on                                      |
|-----------------------|----------|------------------------------------|----------------------------------------------|
| feature_noise         | features | sigma_px (px)                      | pupil and glint centres, every fixation      |
| pupil_decentre        | model    | nasal_mm, superior_mm (mm)         | the pupil centre, every fixation             |
| pupil_change          | model    | delta_diameter_mm (mm)             | pupil size and centre at the validation heads|
| pupil_shift           | model    | nasal_mm, superior_mm (mm)         | the pupil centre at the validation heads     |
| corneal_asphericity   | model    | delta_q                            | the anterior corneal conic constant          |
| corneal_index         | model    | delta_n                            | corneal and aqueous refractive indices       |
| fixation_error        | features | sigma_deg (deg)                    | where each fixation lands (linearised)       |
| head_jitter           | features | sigma_mm (mm)                      | head position of each fixation (linearised)  |
| lens_distortion       | model    | k1                                 | the simulated camera; the host stays pinhole |
| head_roll             | model    | roll_deg (deg)                     | head (eye) roll at the validation heads      |
| tangential_distortion | features | p1, p2                             | image points (Brown decentring distortion)   |
| camera_pose           | model    | pitch_deg, yaw_deg (deg)           | camera orientation, both sessions            |
| camera_bump           | model    | pitch_deg, yaw_deg (deg)           | camera orientation at the validation heads   |
| led_position          | model    | dx_mm, dy_mm (mm)                  | the LEDs' true positions                     |
| screen_position       | model    | dx_mm, dy_mm (mm)                  | the screen's (targets') true position        |
| screen_tilt           | model    | tilt_deg, yaw_deg (deg)            | the screen's orientation                     |
| glint_occlusion       | features | bias                               | the pupil centre where a glint hides its edge|

    from eyehil.emulator.effects import Applied, get, simulate_with
    noise = get("feature_noise")
    features = simulate_with(eyes, scene, [Applied.of(noise, sigma_px=0.1)], rng=np.random.default_rng(1))

Adding an effect: write one class (see `base`) in a module and import it (or `load_module("pkg.mod")`,
or name the module in the environment variable EYEHIL_EFFECT_MODULES, comma-separated).
"""

from __future__ import annotations

import importlib
import importlib.util
import os

from eyehil.emulator.effects.base import REGISTRY, SESSIONS, Applied, Effect, Parameter
from eyehil.emulator.effects.run import sessions, simulate_with

MODULES: list[str] = [f"eyehil.emulator.effects.{m}" for m in
                      ("noise", "pupil", "cornea", "subject", "scene", "camera", "geometry", "occlusion", "anatomy")]
_loaded: set[str] = set()


def load_module(module: str) -> None:
    """Import a module of effect classes (they register themselves); a missing optional module of `MODULES`
    is skipped, any other import error is raised."""
    if module in _loaded:
        return
    if module in MODULES and importlib.util.find_spec(module) is None:
        _loaded.add(module)
        return
    importlib.import_module(module)
    _loaded.add(module)


def _load_all() -> None:
    extra = [m.strip() for m in os.environ.get("EYEHIL_EFFECT_MODULES", "").split(",") if m.strip()]
    for module in [*MODULES, *extra]:
        load_module(module)


def names() -> list[str]:
    """The registered effect names, in registration order."""
    _load_all()
    return list(REGISTRY)


def get(name: str) -> Effect:
    """The effect registered as `name`; ValueError naming the known ones otherwise."""
    _load_all()
    if name not in REGISTRY:
        raise ValueError(f"unknown effect {name!r}; known: {', '.join(REGISTRY)}")
    return REGISTRY[name]()


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


__all__ = ["MODULES", "REGISTRY", "SESSIONS", "Applied", "Effect", "Parameter", "get", "load_module", "names",
           "parse", "sessions", "simulate_with"]
