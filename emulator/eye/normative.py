"""Named normative eyes: single EyeModels (0-d fields; mm, degrees, eye frame of `model.py`) and their media.

- `"navarro"`: Navarro et al. 1985 / Escudero-Sanz & Navarro 1999 (indices at 589 nm). Cornea 7.72 / Q -0.26,
  posterior 6.50 / 0, CCT 0.55, aqueous 3.05, lens 10.20 / -6.00, thickness 4.00, index 1.42, vitreous 16.3203,
  AL 23.9203. The lens asphericities (front Q -3.1316, back Q -1) are not representable (EyeModel lenses are
  spherical): paraxially identical, different off axis.
- `"atchison"`: Atchison 2006 (Vision Res 46:2236), emmetrope (SR 0). Cornea 7.77 / -0.15, posterior 6.40 /
  -0.275, CCT 0.55, aqueous 3.15, lens 11.48 / -5.90 (asphericities -5 and -2 dropped), thickness 3.60
  (1.44 + 2.16), vitreous 16.28, AL 23.58. Its GRIN lens is replaced by the uniform index 1.4319 that makes this
  eye emmetropic paraxially with its media (cornea 1.376, aqueous 1.3374, vitreous 1.336); our derivation.
- `"et_simul"`: Boehme et al. 2008 (ETRA), from its `eye_make.m`: a single refracting sphere R 7.98 in front of
  a medium of index 1.376; pupil radius 3 mm, 3.54 mm behind the apex; alpha 6 deg, beta 2 deg; one rotation
  centre 12.33 mm behind the apex (7.98 + 4.35); cornea edge where its depth reaches 3.54 mm. Its inner corneal
  surface (R 6.22, 1.15 mm thick) only draws; here it is the posterior cornea. An inert posterior cornea and lens
  need cornea = aqueous = lens = vitreous index, which EyeModel cannot say (media are per scene): use
  `normative_media("et_simul")` (1.376 throughout) to reproduce et_simul exactly. The lens (Navarro's radii) and
  AL 23.58 (SR 0) only fill fields et_simul does not have.
- `"mean"`: the Rozema 2011 mean vector converted as in `population.py` (thick-lens index 1.4327), study-code
  media.

Pupil diameters where a model gives none (navarro, atchison): 4.0 mm, a typical pupil in room light (our
choice); `pupil_diameter=` overrides it for every model. Fovea angles and rotation centres other than et_simul's
follow `posterior.py` with the study's scaling.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from eyehil.emulator.eye.biometry import eye_from_biometry
from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.population import eyes_from_raw
from eyehil.emulator.eye.rozema import rozema2011

__all__ = ["NORMATIVE_NAMES", "normative_eye", "normative_media"]

DEFAULT_PUPIL_DIAMETER = 4.0  # mm, for models that specify none
ATCHISON_LENS_INDEX = 1.4319  # uniform index making the Atchison 2006 emmetrope emmetropic (see docstring)
ET_SIMUL_ROTATION_DEPTH = 7.98 + 4.35  # mm behind the apex: cornea centre 4.35 mm in front of the eye centre
ET_SIMUL_CORNEA_DEPTH = 3.54  # mm: depth of the cornea edge (and of the pupil) behind the apex

_SPECS: dict[str, dict[str, float]] = {
    "navarro": {
        "anterior_radius": 7.72, "anterior_conic": -0.26, "posterior_radius": 6.50, "posterior_conic": 0.0,
        "cct": 0.55, "acd": 3.05, "lens_anterior_radius": 10.20, "lens_posterior_radius": 6.00,
        "lens_thickness": 4.00, "axial_length": 23.9203, "lens_index": 1.42,
        "pupil_diameter": DEFAULT_PUPIL_DIAMETER,
    },
    "atchison": {
        "anterior_radius": 7.77, "anterior_conic": -0.15, "posterior_radius": 6.40, "posterior_conic": -0.275,
        "cct": 0.55, "acd": 3.15, "lens_anterior_radius": 11.48, "lens_posterior_radius": 5.90,
        "lens_thickness": 3.60, "axial_length": 23.58, "lens_index": ATCHISON_LENS_INDEX,
        "pupil_diameter": DEFAULT_PUPIL_DIAMETER,
    },
    "et_simul": {
        "anterior_radius": 7.98, "anterior_conic": 0.0, "posterior_radius": 6.22, "posterior_conic": 0.0,
        "cct": 1.15, "acd": ET_SIMUL_CORNEA_DEPTH - 1.15, "lens_anterior_radius": 10.20,
        "lens_posterior_radius": 6.00, "lens_thickness": 4.00, "axial_length": 23.58, "lens_index": 1.376,
        "pupil_diameter": 6.0,
    },
}
_MEDIA: dict[str, Media] = {
    "navarro": Media(cornea=1.376, aqueous=1.3374, vitreous=1.336, label="navarro@589nm"),
    "atchison": Media(cornea=1.376, aqueous=1.3374, vitreous=1.336, label="atchison2006"),
    "et_simul": Media(cornea=1.376, aqueous=1.376, vitreous=1.376, label="et_simul"),
    "mean": Media.study_code(),
}
NORMATIVE_NAMES = ("navarro", "atchison", "et_simul", "mean")


def normative_eye(name: str, laterality: str = "right", *, pupil_diameter: float | None = None) -> EyeModel:
    """The named normative eye (`NORMATIVE_NAMES`) as a single EyeModel; see the module docstring."""
    _check_name(name)
    if name == "mean":
        eye = eyes_from_raw(rozema2011().mean_draw(), "thick-lens", laterality)[0]
    else:
        eye = eye_from_biometry(**_SPECS[name], laterality=laterality)
    if name == "et_simul":
        eye = eye.replace(**_et_simul_fields())
    if pupil_diameter is not None:
        eye = eye.replace(pupil_radius=np.asarray(float(pupil_diameter) / 2.0))
    return eye


def normative_media(name: str) -> Media:
    """The refractive indices the named model was defined with (dimensionless)."""
    _check_name(name)
    return _MEDIA[name]


def _et_simul_fields() -> dict[str, Any]:
    """Fixed fovea angles, one rotation centre and cornea edge of et_simul (right-eye frame, mm, degrees)."""
    centre = np.array([0.0, 0.0, -ET_SIMUL_ROTATION_DEPTH])
    r = _SPECS["et_simul"]["anterior_radius"]
    return {
        "alpha_h": np.asarray(6.0),
        "alpha_v": np.asarray(2.0),
        "azimuth_centre": centre,
        "elevation_centre": centre.copy(),
        "limbus_radius": np.asarray(np.sqrt(r**2 - (r - ET_SIMUL_CORNEA_DEPTH) ** 2)),
    }


def _check_name(name: str) -> None:
    if name not in NORMATIVE_NAMES:
        raise ValueError(f"unknown normative eye {name!r}; known: {', '.join(NORMATIVE_NAMES)}")
