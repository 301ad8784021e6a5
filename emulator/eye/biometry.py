"""Build an EyeModel from biometry: the anterior segment measured or sampled, the posterior segment
(fovea angle, rotation centres) derived from it as in `posterior.py`.
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.posterior import fovea_angles, rotation_centres


def eye_from_biometry(
    *,
    anterior_radius: np.ndarray | float,
    anterior_conic: np.ndarray | float,
    posterior_radius: np.ndarray | float,
    posterior_conic: np.ndarray | float,
    cct: np.ndarray | float,
    acd: np.ndarray | float,
    pupil_diameter: np.ndarray | float,
    lens_anterior_radius: np.ndarray | float,
    lens_posterior_radius: np.ndarray | float,
    lens_thickness: np.ndarray | float,
    axial_length: np.ndarray | float,
    lens_index: np.ndarray | float = 1.42,
    laterality: str = "right",
    fovea_scaling: str = "study",
    centre_scaling: str = "study",
    limbus_radius: float = 5.9,
) -> EyeModel:
    """An eye (scalars) or a batch of eyes (arrays of shape (E,)); mm, `acd` from the posterior cornea.

    `lens_posterior_radius` is the magnitude |R_lp|. The fovea angle and rotation centres are scaled
    with `fovea_scaling` ("study", "gka", "none") and `centre_scaling` ("study", "none").
    """
    if laterality not in ("right", "left"):
        raise ValueError(f"laterality must be 'right' or 'left', not {laterality!r}")
    al = np.asarray(axial_length, dtype=float)
    sr = (23.58 - al) / 0.299
    vitreous = al - np.asarray(acd) - np.asarray(cct) - np.asarray(lens_thickness)
    alpha_h, alpha_v = fovea_angles(vitreous, sr, fovea_scaling)
    azimuth, elevation = rotation_centres(sr, centre_scaling)
    return EyeModel(
        anterior_radius=anterior_radius,
        anterior_conic=anterior_conic,
        posterior_radius=posterior_radius,
        posterior_conic=posterior_conic,
        cct=cct,
        acd=acd,
        pupil_radius=np.asarray(pupil_diameter, dtype=float) / 2.0,
        lens_anterior_radius=lens_anterior_radius,
        lens_posterior_radius=np.abs(np.asarray(lens_posterior_radius, dtype=float)),
        lens_thickness=lens_thickness,
        lens_index=np.broadcast_to(np.asarray(lens_index, dtype=float), al.shape),
        axial_length=al,
        alpha_h=alpha_h,
        alpha_v=alpha_v,
        azimuth_centre=azimuth,
        elevation_centre=elevation,
        left=np.full(al.shape, laterality == "left"),
        limbus_radius=np.full(al.shape, limbus_radius),
        pupil_decentre=np.zeros((*al.shape, 2)),
    )
