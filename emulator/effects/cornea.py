"""The cornea the host's model gets wrong: its asphericity and its refractive index.

The Guestrin & Eizenman 2006 host models the cornea as a sphere of radius R (calibrated) with one
refracting surface of index n1 = 1.3375 (the keratometric index). The simulated eye ray-traces an aspheric
anterior surface (conic constant Q_ac), a posterior surface and separate corneal and aqueous indices.

## Corneal asphericity (`CornealAsphericity`)

Frame: the eye frame; the anterior surface is the conic z = r^2 / (R (1 + sqrt(1 - (1 + Q) r^2 / R^2))).
The effect adds `delta_q` to every eye's Q_ac (kept above -0.95: an ellipsoid). On a population whose
base cornea is spherical (Q = 0) this is the asphericity itself; on the Rozema 2011 eyes (Q_ac about
-0.19 +- 0.16 on the published 100) it is a shift of the population's mean. Glints off the flatter
periphery of a prolate cornea (Q < 0) land where a sphere would put them at a larger radius, which the
sphere-based host turns into errors that grow with eccentricity and head position.
Reference: Navarro, Santamaria & Bescos 1985 (J Opt Soc Am A 2:1273-1281; Q = -0.26); Rozema et al.
2011 (IOVS 52:4525-4533; the population's Q_ac).

## Corneal refractive index (`CornealIndex`)

The corneal and aqueous indices of the simulated eye shifted by `delta_n` (both; dimensionless), while
the host keeps n1 = 1.3375. The apparent pupil the host back-projects through its single surface moves
with the index (the pupil image depth ~ R n / (n - 1) paraxially). Reference: Atchison & Smith 2000
(Optics of the Human Eye: cornea 1.376, aqueous 1.336 at 555 nm; individual corneal indices vary by
about +-0.005: Patel, Marshall & Fitzke 1995, J Refract Surg 11:100-105).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.scene import Scene

MIN_CONIC = -0.95


class CornealAsphericity(Effect):
    """The anterior corneal conic constant Q_ac shifted by delta_q (dimensionless)."""

    name = "corneal_asphericity"
    reference = "Navarro, Santamaria & Bescos 1985, JOSA A 2:1273-1281; Rozema et al. 2011, IOVS 52:4525-4533"
    prior = "Q_ac = -0.26 +- 0.18 in adults (a spherical base cornea: delta_q is Q itself)"
    parameters = (
        Parameter("delta_q", "", 0.0, -0.6, 0.6, doc="added to every eye's anterior conic constant"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        q = np.maximum(eyes.anterior_conic + float(values["delta_q"]), MIN_CONIC)
        return eyes.replace(anterior_conic=q), scene


class CornealIndex(Effect):
    """The corneal and aqueous refractive indices shifted by delta_n (the host keeps n1 = 1.3375)."""

    name = "corneal_index"
    reference = ("Atchison & Smith 2000, Optics of the Human Eye; Patel, Marshall & Fitzke 1995, "
                 "J Refract Surg 11:100-105")
    prior = "0 +- 0.005 between individuals"
    parameters = (
        Parameter("delta_n", "", 0.0, -0.02, 0.02, doc="added to the corneal and the aqueous index"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        shift = float(scene.extra.get("index_shift", 0.0)) + float(values["delta_n"])
        return eyes, replace(scene, extra={**scene.extra, "index_shift": shift})
