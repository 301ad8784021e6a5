"""The anatomical pupil off the optic axis, and its centre moving when the pupil changes size.

Frame: the eye frame of a right eye (mm), x nasal, y superior; `EyeModel.pupil_decentre` holds this
offset of the aperture-stop centre and the ray tracer mirrors it for left eyes. Both effects act before
ray tracing, so the apparent pupil (refracted by the cornea), the fixation (the line of sight passes
through the stop centre) and the ellipse fit all follow.

Measured values (honest summary of the literature used for the defaults and ranges):
- Static decentration: Wildenmann & Schaeffel 2013 (Ophthalmic Physiol Opt 33:634-641; IOVS abstract of
  the same work) found the pupil centre, relative to the corneal centre at 4 mm pupil size, 0.18 +- 0.19 mm
  nasal and 0.30 +- 0.30 mm superior (right eyes, 10 subjects).
- Shift with size: the centre moves nasally when the pupil constricts and temporally when it dilates in
  most observers (Wyatt 1995; Yang, Thompson & Burns 2002; reviewed by Jaschinski 2016, J Eye Mov Res 9(4),
  who gives a mean horizontal shift of about 0.05 mm per mm of diameter change). Wildenmann & Schaeffel
  2013 measured 0.01 +- 0.02 mm/mm horizontally and 0.04 +- 0.05 mm/mm vertically (superior on
  constriction); individuals differ by as much as the means, and shifts of 0.1-0.2 mm/mm occur in single
  subjects. Choe, Blake & Lee 2016 (Vision Res 118:48-59) showed the resulting gaze errors in trackers.
  Defaults here: 0.05 mm/mm nasal and 0.04 mm/mm superior per mm of constriction.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.scene import Scene

MIN_PUPIL_RADIUS_MM = 0.5
LIMBUS_MARGIN_MM = 0.1


class PupilDecentre(Effect):
    """Static decentration of the pupil (mm nasal, mm superior), added to every eye's own."""

    name = "pupil_decentre"
    reference = "Wildenmann & Schaeffel 2013, Ophthalmic Physiol Opt 33:634-641"
    prior = "0.18 +- 0.19 mm nasal, 0.30 +- 0.30 mm superior (at 4 mm pupil; 10 right eyes)"
    twins = ("cornea_decentre",)  # the cornea moved by minus the shift: the same pupil against the corneal centre
    parameters = (
        Parameter("nasal_mm", "mm", 0.0, -0.4, 0.8, doc="pupil centre toward the nose (right eye +x)"),
        Parameter("superior_mm", "mm", 0.0, -0.4, 0.8, doc="pupil centre upward"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        shift = np.array([values["nasal_mm"], values["superior_mm"]])
        return eyes.replace(pupil_decentre=eyes.pupil_decentre + shift), scene


class PupilChange(Effect):
    """Pupil diameter change between calibration and validation, with the centre moving with it."""

    name = "pupil_change"
    reference = ("Wildenmann & Schaeffel 2013, Ophthalmic Physiol Opt 33:634-641; Jaschinski 2016, "
                 "J Eye Mov Res 9(4); Choe, Blake & Lee 2016, Vision Res 118:48-59")
    validation_only = True
    prior = "0 +- 1 mm between sessions under constant light; 2-4 mm with a luminance change"
    parameters = (
        Parameter("delta_diameter_mm", "mm", 0.0, -2.0, 2.0,
                  doc="validation minus calibration pupil diameter (negative: constriction)"),
        Parameter("nasal_per_mm", "mm/mm", 0.05, 0.0, 0.2, fitted=False,
                  doc="nasal shift of the centre per mm of constriction (temporal on dilation)"),
        Parameter("superior_per_mm", "mm/mm", 0.04, -0.1, 0.2, fitted=False,
                  doc="superior shift of the centre per mm of constriction"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        """At validation: radius + delta/2 (kept in [0.5 mm, limbus - 0.1 mm]), centre - delta * shifts."""
        if session != "validation":
            return eyes, scene
        delta = float(values["delta_diameter_mm"])
        radius = np.clip(eyes.pupil_radius + delta / 2, MIN_PUPIL_RADIUS_MM, eyes.limbus_radius - LIMBUS_MARGIN_MM)
        shift = -delta * np.array([values["nasal_per_mm"], values["superior_per_mm"]])
        return eyes.replace(pupil_radius=radius, pupil_decentre=eyes.pupil_decentre + shift), scene


class PupilShift(Effect):
    """The pupil centre moved between calibration and validation (mm nasal, mm superior), size unchanged.

    What a pupil-size change does to a centre-based estimator, without fixing the shift per mm of
    diameter: the observed quantity is the product (shift rate x diameter change), and individuals'
    rates range from -0.1 to +0.2 mm/mm (module docstring), so a 1-2 mm size change moves the centre by
    up to about 0.2-0.3 mm. Frame as `PupilDecentre`; applied at the validation head positions only.
    """

    name = "pupil_shift"
    reference = "Wildenmann & Schaeffel 2013, Ophthalmic Physiol Opt 33:634-641; Jaschinski 2016, J Eye Mov Res 9(4)"
    prior = "0 +- 0.1 mm (rate 0.05 mm/mm x size change 0-2 mm)"
    validation_only = True
    parameters = (
        Parameter("nasal_mm", "mm", 0.0, -0.3, 0.3, doc="validation minus calibration, toward the nose"),
        Parameter("superior_mm", "mm", 0.0, -0.3, 0.3, doc="validation minus calibration, upward"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        if session != "validation":
            return eyes, scene
        shift = np.array([values["nasal_mm"], values["superior_mm"]])
        return eyes.replace(pupil_decentre=eyes.pupil_decentre + shift), scene
