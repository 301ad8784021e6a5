"""The optical surfaces of an EyeModel in its eye-local frame (the unrotated eye frame, mm).

Anterior cornea: apex 0, (R_ac, Q_ac), aperture = limbus radius. Posterior cornea: apex -CCT,
(R_pc, Q_pc). Pupil (aperture stop) plane: z = -(CCT + ACD). Lens: spheres of radius R_la (apex at the
stop) and -R_lp (apex at the stop - T). Retina: an ellipsoid centred on the axis (`posterior.py`).
`shape` appends singleton axes so that eye parameters of shape (E,) broadcast against batches of
shape (E, ...).
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.posterior import retina_centre_depth, retina_semi_axes
from eyehil.emulator.optics.conic import Conic, Plane
from eyehil.emulator.optics.pupil import CorneaOptics

LENS_APERTURE_MM = 4.5


def _b(value: np.ndarray, extra_dims: int) -> np.ndarray:
    return np.asarray(value, dtype=float).reshape(np.shape(value) + (1,) * extra_dims)


def cornea_optics(eye: EyeModel, media: Media, extra_dims: int = 0) -> CorneaOptics:
    """Anterior and posterior cornea, pupil plane and indices, broadcastable over `extra_dims` axes."""
    zero = np.zeros(eye.shape)
    return CorneaOptics(
        anterior=Conic(zero, eye.anterior_radius, eye.anterior_conic, eye.limbus_radius).reshaped(extra_dims),
        posterior=Conic(-eye.cct, eye.posterior_radius, eye.posterior_conic, eye.limbus_radius).reshaped(extra_dims),
        pupil_plane=Plane(_b(-eye.stop_depth, extra_dims)),
        n_air=np.asarray(media.air),
        n_cornea=np.asarray(media.cornea),
        n_aqueous=np.asarray(media.aqueous),
    )


def lens_surfaces(eye: EyeModel, extra_dims: int = 0) -> tuple[Conic, Conic]:
    """(anterior, posterior) lens surfaces."""
    zero = np.zeros(eye.shape)
    aperture = np.full(eye.shape, LENS_APERTURE_MM)
    front = Conic(-eye.stop_depth, eye.lens_anterior_radius, zero, aperture)
    back = Conic(-eye.stop_depth - eye.lens_thickness, -eye.lens_posterior_radius, zero, aperture)
    return front.reshaped(extra_dims), back.reshaped(extra_dims)


def retina(eye: EyeModel, extra_dims: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(centre (..., 3), semi-axes (..., 3) in x, y, z) of the retinal ellipsoid."""
    sr = eye.spherical_refraction
    axes = retina_semi_axes(sr)[..., [1, 2, 0]]
    centre = np.stack(np.broadcast_arrays(0.0, 0.0, retina_centre_depth(eye.axial_length, sr)), axis=-1)
    pad = (1,) * extra_dims
    return centre.reshape(eye.shape + pad + (3,)), axes.reshape(eye.shape + pad + (3,))


def pupil_centre(eye: EyeModel) -> np.ndarray:
    """(..., 3) centre of the aperture stop in the eye-local frame (decentration mirrored for left eyes)."""
    x = eye.pupil_decentre[..., 0] * eye.side_sign
    return np.stack([x, eye.pupil_decentre[..., 1], -eye.stop_depth], axis=-1)
