"""Anatomy beyond the published study as named effects: toric corneas, corneal tilt and decentration, an
elliptical stop (issue 13). Each acts before ray tracing (stage "model", every session) on the eyes' own
anatomy (`eyehil.emulator.eye.model`: right-eye frame, x nasal, y superior; left eyes mirrored by the tracer) and is
the identity at its neutral values.

| name                | fitted parameters                  | acts on                                          |
|---------------------|------------------------------------|--------------------------------------------------|
| corneal_astigmatism | anterior_j0_d, anterior_j45_d (D)  | adds a power vector to the anterior cornea        |
|                     | (posterior_j0_d, posterior_j45_d)  | and, unfitted, to the posterior one              |
| cornea_tilt         | nasal_deg, superior_deg (deg)      | turns the cornea about a point 14.26 mm deep      |
| cornea_decentre     | nasal_mm, superior_mm (mm)         | moves the cornea (both surfaces) off the axis     |
| pupil_ellipse       | eccentricity (1)                   | makes the stop an ellipse of the same area        |

Registration: `ANATOMY_EFFECTS` maps each name to "module:Class" in the form of `eyehil.emulator.effects.EFFECTS`
(the table the discrepancy workflow reads); merge it there to make the names known to `effects.get`.
The pupil centre moving with pupil size is `EyeModel.pupil_shift_per_mm` (used by `with_pupil_diameter`);
the size change between sessions is the existing `pupil_change` effect.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter
from eyehil.emulator.eye.anatomy import GKA_STOP_THETA_DEG, tilted_about_centre
from eyehil.emulator.eye.astigmatism import ANTERIOR_DN, POSTERIOR_DN, power_vector, principal_radii
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.scene import Scene

ANATOMY_EFFECTS: dict[str, str] = {
    "corneal_astigmatism": "eyehil.emulator.effects.anatomy:CornealAstigmatism",
    "cornea_tilt": "eyehil.emulator.effects.anatomy:CorneaTilt",
    "cornea_decentre": "eyehil.emulator.effects.anatomy:CorneaDecentre",
    "pupil_ellipse": "eyehil.emulator.effects.anatomy:PupilEllipse",
}


def _add_power_vector(eyes: EyeModel, surface: str, j0: float, j45: float, dn: float) -> EyeModel:
    r, rp, axis = (getattr(eyes, f"{surface}_{k}") for k in ("radius", "radius_perp", "axis_deg"))
    m, own_j0, own_j45 = power_vector(r, rp, axis, dn)
    r, rp, axis = principal_radii(m, own_j0 + j0, own_j45 + j45, dn)
    return eyes.replace(**{f"{surface}_radius": r, f"{surface}_radius_perp": rp, f"{surface}_axis_deg": axis})


class CornealAstigmatism(Effect):
    """Corneal astigmatism: power vectors (J0, J45; D) added to the anterior and posterior cornea."""

    name = "corneal_astigmatism"
    prior = "anterior J0 0.30 +- 0.29 D, J45 0.06 +- 0.23 D (Rozema 2011; with-the-rule in most adults)"
    reference = ("Thibos, Wheeler & Horner 1997, Optom Vis Sci 74:367-375 (power vectors); Rozema, Atchison & "
                 "Tassignon 2011, IOVS 52:4525-4533 (population: anterior J0 0.30 +- 0.29 D, J45 0.06 +- 0.23 D)")
    parameters = (
        Parameter("anterior_j0_d", "D", 0.0, -1.5, 1.5, doc="anterior J0 (> 0 with the rule: vertical steeper)"),
        Parameter("anterior_j45_d", "D", 0.0, -1.0, 1.0, doc="anterior J45 (right eye; mirrored for left eyes)"),
        Parameter("posterior_j0_d", "D", 0.0, -0.5, 0.5, fitted=False, doc="posterior J0"),
        Parameter("posterior_j45_d", "D", 0.0, -0.3, 0.3, fitted=False, doc="posterior J45"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        """Each surface: its own (M, J0, J45) plus the given J0, J45; M (the study's radius) unchanged."""
        ant = (values["anterior_j0_d"], values["anterior_j45_d"])
        post = (values["posterior_j0_d"], values["posterior_j45_d"])
        if any(ant):
            eyes = _add_power_vector(eyes, "anterior", *ant, ANTERIOR_DN)
        if any(post):
            eyes = _add_power_vector(eyes, "posterior", *post, POSTERIOR_DN)
        return eyes, scene


class CorneaTilt(Effect):
    """Tilt of the cornea (both surfaces) about gkaModelEye's corneal centre, 14.26 mm deep (deg nasal, superior)."""

    name = "cornea_tilt"
    prior = "about 2.5 deg nasal (gkaModelEye, Navarro 2006); the spread between eyes is not well published"
    reference = ("Navarro, Gonzalez & Hernandez 2006, JOSA A 23:219-232; gkaModelEye (Aguirre 2019) uses 2.5 deg "
                 "nasal")
    parameters = (
        Parameter("nasal_deg", "deg", 0.0, -5.0, 5.0, doc="corneal axis turned toward the nose (right eye +x)"),
        Parameter("superior_deg", "deg", 0.0, -5.0, 5.0, doc="corneal axis turned upward"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        if not (values["nasal_deg"] or values["superior_deg"]):
            return eyes, scene
        return tilted_about_centre(eyes, values["nasal_deg"], values["superior_deg"]), scene


class CorneaDecentre(Effect):
    """Displacement of the cornea (both surfaces) from the optic axis of pupil and lens (mm nasal, mm superior)."""

    name = "cornea_decentre"
    prior = "tenths of a mm; gkaModelEye puts the apex 0.62 mm nasal of the stop's axis"
    reference = "gkaModelEye (Aguirre 2019): the turned cornea's apex lies 0.62 mm nasal of the stop's axis"
    twins = ("pupil_decentre",)  # the pupil moved by minus the shift: the same pupil against the corneal centre
    parameters = (
        Parameter("nasal_mm", "mm", 0.0, -1.0, 1.0, doc="corneal apex toward the nose (right eye +x)"),
        Parameter("superior_mm", "mm", 0.0, -1.0, 1.0, doc="corneal apex upward"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        if not (values["nasal_mm"] or values["superior_mm"]):
            return eyes, scene
        shift = np.array([values["nasal_mm"], values["superior_mm"], 0.0])
        return eyes.replace(cornea_offset=eyes.cornea_offset + shift), scene


class PupilEllipse(Effect):
    """Elliptical aperture stop of the pupil's area: eccentricity and major-axis angle (deg, nasal -> up)."""

    name = "pupil_ellipse"
    prior = "eccentricity 0 to about 0.12 (Wyatt 1995; gkaModelEye's stop)"
    reference = ("Wyatt 1995, Vision Res 35:2021-2036; gkaModelEye's stop (eccentricity up to about 0.12, "
                 "axis 0 or 77 deg)")
    parameters = (
        Parameter("eccentricity", "1", 0.0, 0.0, 0.4, doc="stop eccentricity sqrt(1 - b^2 / a^2)"),
        Parameter("axis_deg", "deg", float(GKA_STOP_THETA_DEG), 0.0, 180.0, fitted=False,
                  doc="major axis from nasal toward superior (right eye)"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        """Replaces the stop's own shape; at eccentricity 0 the eyes are left as they are."""
        if not values["eccentricity"]:
            return eyes, scene
        e = np.full(eyes.shape, float(values["eccentricity"]))
        return eyes.replace(pupil_eccentricity=e, pupil_axis_deg=np.full(eyes.shape, float(values["axis_deg"]))), scene
