"""Corneal astigmatism: keratometric power vectors (M, J0, J45) <-> principal radii and cylinder axis.

Convention (Thibos, Wheeler & Horner 1997, Optom Vis Sci 74:367-375, "Power vectors"; used for corneal
power by Rozema, Atchison & Tassignon 2011, whose SyntEyes population draws them): a sphero-cylinder with
minus cylinder C < 0 at axis alpha has M = S + C/2, J0 = -(C/2) cos 2 alpha, J45 = -(C/2) sin 2 alpha, so
the power in the meridian at angle theta is

    K(theta) = M - J0 cos 2 theta - J45 sin 2 theta.

Angles are TABO: in the plane of the eye as the examiner faces it, 0 deg at the examiner's right (the
subject's left), increasing counter-clockwise. In the eye frame of a right eye (`model.py`: x toward the
subject's left = nasal, y up, z toward the examiner) theta runs from +x toward +y. J0 > 0 is "with the
rule" (the vertical meridian has the most power): the population's anterior cornea (J0 = +0.30 D) is
with the rule and its posterior (J0 = -0.17 D, the surface's power being negative) is steeper vertically
too, which reads as against the rule in power. Principal meridians: the least power M - |J| lies at the
minus-cylinder axis theta_a = atan2(J45, J0) / 2 and the most, M + |J|, at theta_a + 90 deg.

Radii from powers as in the population conversion (`population.py`): R = 1000 dn / K (mm, K in D) with
dn = 0.3372 for the anterior surface (keratometric index 1.3372: R = 337.2 / K) and dn = -0.0408 for the
posterior one (R = -40.8 / K with K < 0).

Left eyes: a left eye is the mirror image (x -> -x) of its right-eye anatomy, so theta -> 180 - theta:
J0 is unchanged and J45 changes sign (the usual "mirror symmetry" of fellow eyes' oblique astigmatism).
The EyeModel stores right-eye values and mirrors them when it builds the surfaces (`surfaces.py`).

Known answer: M = 43 D, J0 = 0.5 D, J45 = 0 gives radii 337.2 / 42.5 = 7.934 mm at axis 0 deg (horizontal,
flatter) and 337.2 / 43.5 = 7.752 mm at 90 deg.
"""

from __future__ import annotations

import numpy as np

ANTERIOR_DN = 0.3372  # keratometric index - 1 (Rozema / the study: R_ac = 337.2 / K)
POSTERIOR_DN = -0.0408  # (1.3372 - 1.378): R_pc = -40.8 / K_post


def principal_radii(
    mean_power: np.ndarray, j0: np.ndarray, j45: np.ndarray, dn: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R at the axis, R at axis + 90, axis in degrees [0, 180)) from M, J0, J45 (D); see the module docstring."""
    m, j0, j45 = (np.asarray(v, dtype=float) for v in (mean_power, j0, j45))
    magnitude = np.hypot(j0, j45)
    axis = np.mod(np.degrees(0.5 * np.arctan2(j45, j0)), 180.0)
    return 1000.0 * dn / (m - magnitude), 1000.0 * dn / (m + magnitude), axis


def power_vector(
    radius: np.ndarray, radius_perp: np.ndarray, axis_deg: np.ndarray, dn: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, J0, J45) in D of a surface with `radius` in the meridian `axis_deg` and `radius_perp` 90 deg away."""
    k_axis = 1000.0 * dn / np.asarray(radius, dtype=float)
    k_perp = 1000.0 * dn / np.asarray(radius_perp, dtype=float)
    half_cyl = 0.5 * (k_axis - k_perp)  # C / 2 with the cylinder's axis at axis_deg
    two = np.radians(2.0 * np.asarray(axis_deg, dtype=float))
    return 0.5 * (k_axis + k_perp), -half_cyl * np.cos(two), -half_cyl * np.sin(two)


def mirrored_j45(j45: np.ndarray) -> np.ndarray:
    """J45 of the fellow (mirror-image) eye: -J45 (J0 and M are unchanged)."""
    return -np.asarray(j45, dtype=float)
