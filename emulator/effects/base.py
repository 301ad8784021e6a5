"""The interface of a model extension ("effect"): named parameters, and two hooks into the forward model.

A user adds an effect by writing one subclass of `Effect` with a `name`: defining the class registers it
(`Effect.__init_subclass__` -> `REGISTRY`), so it is in the catalogue as soon as its module is imported
(`eyehil.emulator.effects.MODULES` lists the catalogue's modules, `eyehil.emulator.effects.load_module` adds one).
Every effect documents its physics, parameters with units and plausible range, a `prior` (typical value
and spread in the population, for orientation and for drawing test strengths) and a `reference`.

An effect acts at one or both of two stages of `simulate_with` (`eyehil.emulator.effects.run`):

- `apply(eyes, scene, values, session) -> (eyes, scene)`: before ray tracing, on the anatomy (an
  `EyeModel` batch) or on the scene (camera, head positions). `session` is "calibration" (head position 0)
  or "validation" (the other head positions), so that an effect can change something between the
  fixations a host calibrates on and the ones it is judged on.
- `perturb(features, values, rng) -> features`: after ray tracing, on the image features (px), with an
  explicit `numpy.random.Generator`.

A `perturb` that needs how the features respond to a small geometric change (a fixation or head
displacement per fixation) sets `needs_sensitivity` and computes it once in `sensitivity(eyes, scene,
session, heads)` (by ray tracing displaced copies); the runner caches it per effect and passes it to
`perturb(..., sensitivity=...)`: such an effect costs no ray tracing per parameter value.

An effect names its `twins`: effects of the catalogue that change every feature and gaze error alike, to well
below the spread between eyes, at matched values (a decentred pupil and a cornea decentred the other way move
the pupil against the corneal centre identically). No recording tells twins apart, whatever its number of eyes;
a report names the twins of what it adds, and a blind trial of an effect "outside the catalogue" removes its
twins with it (`eyehil.analysis.discrepancy.trials`). tests/test_effect_twins.py checks every declaration.

The host never learns about an effect: a scene changed by `apply` is the truth of the simulation, while the
host keeps the nominal scene (e.g. a lens distortion it does not correct). Every effect is the identity at
its parameters' `neutral` values. Values are a plain mapping {parameter name: float} in the units of
`Parameter.unit`; `Effect.values(...)` fills defaults and checks names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene

SESSIONS = ("calibration", "validation")
REGISTRY: dict[str, type[Effect]] = {}


@dataclass(frozen=True)
class Parameter:
    """One parameter: name, unit, default (the value it takes unless given), plausible range [low, high],
    the value at which the effect does nothing (`neutral`), whether the discrepancy search fits it, and a
    one-line meaning. `neutral` lies outside [low, high] for a parameter that shapes an effect another parameter
    switches off (glint occlusion's radius: its bias)."""

    name: str
    unit: str
    default: float
    low: float
    high: float
    neutral: float = 0.0
    fitted: bool = True
    doc: str = ""

    @property
    def switches_off(self) -> bool:
        """Whether this parameter alone can switch the effect off: its neutral value is inside [low, high]."""
        return self.low <= self.neutral <= self.high


class Effect:
    """Base class: subclasses set `name`, `parameters`, `reference`, `stage` and override a hook.

    `stage` is "model" (acts in `apply`) or "features" (acts in `perturb`); `validation_only` says the
    effect changes nothing at the calibration head position (it needs a scene with more than one).
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    reference: ClassVar[str] = ""
    prior: ClassVar[str] = ""  # typical value +- spread in the population, in words with units
    stage: ClassVar[str] = "model"
    validation_only: ClassVar[bool] = False
    needs_sensitivity: ClassVar[bool] = False
    twins: ClassVar[tuple[str, ...]] = ()  # effects no data can tell from this one (module docstring)

    def __init_subclass__(cls, **kwargs: object) -> None:
        """A subclass with a `name` joins the registry (a later class of the same name replaces it)."""
        super().__init_subclass__(**kwargs)
        if cls.name:
            REGISTRY[cls.name] = cls

    @property
    def fitted(self) -> tuple[Parameter, ...]:
        """The parameters a search adjusts, in order."""
        return tuple(p for p in self.parameters if p.fitted)

    def acts_in(self, session: str) -> bool:
        """Whether `apply` can change the ray tracing of `session` (a features effect never does)."""
        return self.stage == "model" and (session == "validation" or not self.validation_only)

    def parameter(self, name: str) -> Parameter:
        """The parameter called `name`."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise ValueError(f"effect {self.name!r} has no parameter {name!r}; it has {self.names()}")

    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def values(self, given: Mapping[str, float] | None = None, **more: float) -> dict[str, float]:
        """Every parameter's value: the defaults, overridden by `given` and `more` (names checked)."""
        out = {p.name: float(p.default) for p in self.parameters}
        for name, value in {**(given or {}), **more}.items():
            self.parameter(name)
            out[name] = float(value)
        return out

    def neutral(self) -> dict[str, float]:
        """Values at which the effect is the identity."""
        return {p.name: (float(p.neutral) if p.fitted else float(p.default)) for p in self.parameters}

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        """The anatomy and scene the simulation uses in `session` (default: unchanged)."""
        return eyes, scene

    def perturb(self, features: Features, values: Mapping[str, float],
                rng: np.random.Generator | None, **kwargs: object) -> Features:
        """The features as the host receives them (default: unchanged); `sensitivity=` for effects that
        set `needs_sensitivity`."""
        return features

    def sensitivity(self, eyes: EyeModel, scene: Scene, session: str, heads: tuple) -> dict[str, np.ndarray]:
        """Derivatives of the features of one session with respect to this effect's displacement
        (effects with `needs_sensitivity`; arrays shaped like the features with a trailing axis)."""
        raise NotImplementedError(f"effect {self.name!r} has no sensitivity")

    def summary(self) -> str:
        """The first line of the docstring."""
        return (self.__doc__ or "").strip().splitlines()[0]

    def __repr__(self) -> str:
        return f"<effect {self.name}>"


@dataclass(frozen=True, eq=False)
class Applied:
    """An effect at given parameter values (every parameter present; see `Effect.values`)."""

    effect: Effect
    values: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def of(cls, effect: Effect, given: Mapping[str, float] | None = None, **more: float) -> Applied:
        """`effect` at its defaults overridden by `given` / `more`."""
        return cls(effect, effect.values(given, **more))

    def label(self) -> str:
        """`name(p=v unit, ...)` of the fitted parameters."""
        parts = [f"{p.name}={self.values[p.name]:.4g} {p.unit}".rstrip() for p in self.effect.fitted]
        return f"{self.effect.name}({', '.join(parts)})"


def with_arrays(features: Features, **arrays: np.ndarray) -> Features:
    """A shallow copy of `features` with some arrays replaced."""
    return replace(features, arrays={**features.arrays, **arrays})
