"""The optical surfaces of an EyeModel in its eye-local frame (the unrotated eye frame, mm).

Anterior cornea: apex 0, (R_ac, Q_ac), aperture = limbus radius. Posterior cornea: apex -CCT,
(R_pc, Q_pc). Pupil (aperture stop) plane: z = -(CCT + ACD). Lens: spheres of radius R_la (apex at the
stop) and -R_lp (apex at the stop - T). Retina: an ellipsoid centred on the axis (`posterior.py`).
`shape` appends singleton axes so that eye parameters of shape (E,) broadcast against batches of
shape (E, ...).

A batch in which every eye is `rotationally_symmetric` gets `Conic` corneas (the published model, traced
exactly as before); otherwise both corneal surfaces are `Biconic`s: principal meridians at the axis angles,
the cornea tilted about the anterior apex by `cornea_tilt_deg` and displaced by `cornea_offset` (the
posterior apex sits CCT behind the anterior one along the tilted axis). Left eyes mirror x: axis angles
theta -> -theta, horizontal tilt and offsets change sign in the eye-local frame.
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.posterior import retina_centre_depth, retina_semi_axes
from eyehil.emulator.optics.biconic import Biconic, rotation_matrix
from eyehil.emulator.optics.conic import Conic, Plane
from eyehil.emulator.optics.pupil import CorneaOptics

LENS_APERTURE_MM = 4.5


def _b(value: np.ndarray, extra_dims: int) -> np.ndarray:
    return np.asarray(value, dtype=float).reshape(np.shape(value) + (1,) * extra_dims)


def cornea_optics(eye: EyeModel, media: Media, extra_dims: int = 0) -> CorneaOptics:
    """Anterior and posterior cornea, pupil plane and indices, broadcastable over `extra_dims` axes."""
    if np.all(eye.rotationally_symmetric):
        zero = np.zeros(eye.shape)
        anterior = Conic(zero, eye.anterior_radius, eye.anterior_conic, eye.limbus_radius).reshaped(extra_dims)
        posterior = Conic(-eye.cct, eye.posterior_radius, eye.posterior_conic, eye.limbus_radius).reshaped(extra_dims)
    else:
        anterior, posterior = (s.reshaped(extra_dims) for s in biconic_cornea(eye))
    return CorneaOptics(
        anterior=anterior,
        posterior=posterior,
        pupil_plane=Plane(_b(-eye.stop_depth, extra_dims)),
        n_air=np.asarray(media.air),
        n_cornea=np.asarray(media.cornea),
        n_aqueous=np.asarray(media.aqueous),
    )


def cornea_pose(eye: EyeModel) -> tuple[np.ndarray, np.ndarray]:
    """(anterior apex (..., 3), tilt rotation (..., 3, 3)) of the cornea in the eye-local frame (mirrored)."""
    apex = eye.frame_vector(eye.cornea_offset)
    tilt = rotation_matrix(0.0, eye.cornea_tilt_deg[..., 0] * eye.side_sign, eye.cornea_tilt_deg[..., 1])
    return apex, tilt


def biconic_cornea(eye: EyeModel) -> tuple[Biconic, Biconic]:
    """(anterior, posterior) corneal surfaces as biconics in the eye-local frame (see the module docstring)."""
    apex, tilt = cornea_pose(eye)
    s = eye.side_sign
    front = tilt @ rotation_matrix(eye.anterior_axis_deg * s, 0.0, 0.0)
    back = tilt @ rotation_matrix(eye.posterior_axis_deg * s, 0.0, 0.0)
    back_apex = apex - eye.cct[..., None] * tilt[..., :, 2]
    return (
        Biconic(apex, front, eye.anterior_radius, eye.anterior_radius_perp, eye.anterior_conic,
                eye.anterior_conic_perp, eye.limbus_radius),
        Biconic(back_apex, back, eye.posterior_radius, eye.posterior_radius_perp, eye.posterior_conic,
                eye.posterior_conic_perp, eye.limbus_radius),
    )


def cornea_centre(eye: EyeModel) -> np.ndarray:
    """(..., 3) centre of the anterior cornea's (mean-curvature) osculating sphere, eye-local frame."""
    if np.all(eye.rotationally_symmetric):
        zeros = np.zeros(eye.shape)
        return np.stack([zeros, zeros, -eye.anterior_radius], axis=-1)
    apex, tilt = cornea_pose(eye)
    return apex - eye.anterior_mean_radius[..., None] * tilt[..., :, 2]


def cornea_apex(eye: EyeModel) -> np.ndarray:
    """(..., 3) anterior corneal apex in the eye-local frame (the origin unless the cornea is displaced)."""
    return eye.frame_vector(eye.cornea_offset)


def stop_ellipse(eye: EyeModel) -> tuple[np.ndarray, np.ndarray]:
    """(eccentricity, major-axis angle in the eye-local frame, deg) of the aperture stop (mirrored)."""
    return eye.pupil_eccentricity, eye.pupil_axis_deg * eye.side_sign


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
