"""Posterior segment, fovea angle and rotation centres (gkaModelEye, Aguirre 2019, Sci Rep 9:9360).

gkaModelEye figures are [p1 depth, p2 horizontal (nasal for a right eye), p3 vertical]; here they
are mapped to the eye frame (x, y, z) = (p2, p3, p1) of a right eye; `EyeModel.left` mirrors x.

- Retina: ellipsoid with semi-axes [axial, horizontal, vertical] = [10.148, 11.455, 11.365]
  + [-0.163, -0.043, -0.090] * SR, posterior pole at depth -AL.
- Fovea angle of an emmetrope alpha0 = (5.45, 2.5) deg (nasal, superior); the published study scales it
  with the vitreous length: alpha = atan((16.182 / vitreous_length) tan(alpha0)); gkaModelEye scales it
  with SR: alpha = atan(16.5 / (16.5 - 0.299 SR) tan(alpha0)).
- Rotation centres: azimuth [-14.7, 0.79, 0], elevation [-12.0, 0, 0.33] (p1, p2, p3); the study scales
  them with x = retina_semi_axes(SR) / retina_semi_axes(0): azimuth * x1 * x2, elevation * x1 / x2.
"""

from __future__ import annotations

import numpy as np

RETINA_AXES_EMMETROPE = np.array([10.148, 11.455, 11.365])  # [axial, horizontal, vertical] mm
RETINA_AXES_PER_DIOPTRE = np.array([-0.163, -0.043, -0.090])
FOVEA_ANGLE_EMMETROPE = (5.45, 2.5)  # deg (nasal, superior)
AZIMUTH_CENTRE = np.array([0.79, 0.0, -14.7])  # eye frame (x nasal, y up, z depth), right eye
ELEVATION_CENTRE = np.array([0.0, 0.33, -12.0])
STUDY_VITREOUS_LENGTH = 16.182  # mm: the vitreous length of the mean Rozema eye


def retina_semi_axes(spherical_refraction: np.ndarray) -> np.ndarray:
    """(..., 3) semi-axes [axial, horizontal, vertical] of the retinal ellipsoid (mm)."""
    sr = np.asarray(spherical_refraction, dtype=float)[..., None]
    return RETINA_AXES_EMMETROPE + RETINA_AXES_PER_DIOPTRE * sr


def fovea_angles(
    vitreous_length: np.ndarray,
    spherical_refraction: np.ndarray,
    scaling: str = "study",
    alpha0: tuple[float, float] = FOVEA_ANGLE_EMMETROPE,
) -> tuple[np.ndarray, np.ndarray]:
    """Fovea angles (nasal, superior) in degrees, scaled by `"study"`, `"gka"` or `"none"`."""
    if scaling == "study":
        factor = STUDY_VITREOUS_LENGTH / np.asarray(vitreous_length, dtype=float)
    elif scaling == "gka":
        factor = 16.5 / (16.5 - 0.299 * np.asarray(spherical_refraction, dtype=float))
    elif scaling == "none":
        factor = np.ones_like(np.asarray(vitreous_length, dtype=float))
    else:
        raise ValueError(f"fovea scaling must be 'study', 'gka' or 'none', not {scaling!r}")
    h, v = (np.degrees(np.arctan(factor * np.tan(np.radians(a)))) for a in alpha0)
    return h, v


def rotation_centres(spherical_refraction: np.ndarray, scaling: str = "study") -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) rotation centres, (..., 3) in the eye frame of a right eye (mm)."""
    sr = np.asarray(spherical_refraction, dtype=float)
    if scaling == "none":
        return np.broadcast_to(AZIMUTH_CENTRE, (*sr.shape, 3)).copy(), np.broadcast_to(
            ELEVATION_CENTRE, (*sr.shape, 3)
        ).copy()
    if scaling != "study":
        raise ValueError(f"rotation-centre scaling must be 'study' or 'none', not {scaling!r}")
    x = retina_semi_axes(sr) / RETINA_AXES_EMMETROPE
    x1, x2 = x[..., 0:1], x[..., 1:2]
    return AZIMUTH_CENTRE * x1 * x2, ELEVATION_CENTRE * x1 / x2


def retina_centre_depth(axial_length: np.ndarray, spherical_refraction: np.ndarray) -> np.ndarray:
    """z of the retinal ellipsoid's centre: posterior pole at -AL, so -AL + axial semi-axis."""
    return -np.asarray(axial_length, dtype=float) + retina_semi_axes(spherical_refraction)[..., 0]
