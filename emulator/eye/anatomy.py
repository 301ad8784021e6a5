"""The anatomy the published study left out, added to given eyes: `full_anatomy(eyes, rng)` (issue 13).

The published study (Fischer et al. 2023) used conic corneas of revolution about the optic axis and a circular
pupil centred on it. `full_anatomy` keeps every published parameter of the eyes and adds:

- Corneal astigmatism: the anterior and posterior power vectors (J0, J45) drawn from the Rozema 2011 normal
  conditionally on what the eye already has (K_ant_M = 337.2 / R_ac, K_post_M = -40.8 / R_pc, R_la, -|R_lp|,
  T, CCT, ACD, AL, pupil diameter; the eccentricities are left out because Q = -e^2 has lost their sign, as
  in `published.conditional_lens_power`), then converted to toric corneas (`astigmatism.py`). The mean powers
  (and so R_ac, R_pc of the study) are unchanged.
- Pupil decentration: the stop centre relative to the corneal axis at a 4 mm pupil drawn from
  N(0.18 +- 0.19 mm nasal, 0.30 +- 0.30 mm superior) (Wildenmann & Schaeffel 2013, Ophthalmic Physiol Opt
  33:634-641, 10 right eyes); its movement with pupil size drawn from N(-0.01 +- 0.02, -0.04 +- 0.05) mm per
  mm of diameter increase (the same study: the centre moves nasally and up on constriction), and the eye's
  own pupil is placed accordingly: decentre = decentre_4mm + shift * (diameter - 4 mm). The two components
  are drawn independently (no covariance is published). Checked on 2026-12-02 against the same group's
  meeting abstract (Invest Ophthalmol Vis Sci 2013, iovs.arvojournals.org article 2146525: right eyes at 4 mm,
  0.18 +- 0.19 mm nasal and 0.30 +- 0.30 mm superior; change per mm of pupil size 0.01 +- 0.02 mm horizontally
  and 0.04 +- 0.05 mm vertically, the decentration growing on constriction); the left eyes there, -0.14 +-
  0.22 mm and 0.27 +- 0.29 mm, are not used (a left eye here is the right eye's mirror).
- Elliptical stop: gkaModelEye's stop (Aguirre 2019, after Wyatt 1995, Vision Res 35:2021-2036, and Mathur et
  al. 2013): eccentricity e(r) = 0.103 (tanh(4.784 (r - 1.743)) + 0.149) of the stop radius r (mm); e < 0 is
  a horizontal major axis, e > 0 one at 3 pi / 7 (77.1 deg from nasal toward superior, right eye); |e| is
  used. Same area as the circle of the eye's pupil radius. No between-subject spread (the model's mean).
- Cornea tilt: gkaModelEye's default, after Navarro, Gonzalez & Hernandez 2006 (JOSA A 23:219-232): the
  corneal ellipsoid turned 2.5 deg about the vertical axis toward the nasal side, about its own centre, which
  in gkaModelEye lies 14.26 mm behind the apex; the apex moves 14.26 sin(2.5 deg) = 0.62 mm nasally and
  0.014 mm back. The pivot stays at that depth for every eye (an eye's own ellipsoid centre, R / (1 + Q),
  lies up to 39 mm deep for the most prolate published corneas, which would move their apex 1.7 mm). No
  between-subject spread (none that we could verify).

Every component can be switched off; with all off the eyes come back unchanged.
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.population import with_power_vectors
from eyehil.emulator.eye.rozema import rozema2011

__all__ = ["CORNEA_TILT_DEG", "PUPIL_DECENTRE_MEAN_MM", "PUPIL_DECENTRE_SD_MM", "PUPIL_SHIFT_MEAN_MM_PER_MM",
           "PUPIL_SHIFT_SD_MM_PER_MM", "conditional_astigmatism", "full_anatomy", "gka_stop",
           "tilted_about_centre"]

PUPIL_REFERENCE_DIAMETER_MM = 4.0  # Wildenmann & Schaeffel 2013 report the decentration at 4 mm
PUPIL_DECENTRE_MEAN_MM = np.array([0.18, 0.30])  # nasal, superior
PUPIL_DECENTRE_SD_MM = np.array([0.19, 0.30])
PUPIL_SHIFT_MEAN_MM_PER_MM = np.array([-0.01, -0.04])  # per mm of diameter increase (nasal, superior)
PUPIL_SHIFT_SD_MM_PER_MM = np.array([0.02, 0.05])
GKA_STOP_PARAMS = (-1.743, 4.784, 0.149, 0.103)  # gkaModelEye human stop: (tanh((r + p0) p1) + p2) p3
GKA_STOP_THETA_DEG = np.degrees(3.0 * np.pi / 7.0)  # right eye, for e > 0; 0 deg for e < 0
CORNEA_TILT_DEG = 2.5  # nasal, about the vertical axis (gkaModelEye, Navarro 2006)
CORNEA_PIVOT_DEPTH_MM = 14.26  # gkaModelEye's anterior corneal ellipsoid centre behind the apex (its axial semi-axis)
ASTIGMATISM_NAMES = ("K_ant_J0", "K_ant_J45", "K_post_J0", "K_post_J45")


def gka_stop(stop_radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eccentricity >= 0, major-axis angle in degrees, right eye) of gkaModelEye's stop of radius r (mm)."""
    p0, p1, p2, p3 = GKA_STOP_PARAMS
    e = (np.tanh((np.asarray(stop_radius, dtype=float) + p0) * p1) + p2) * p3
    return np.abs(e), np.where(e > 0, GKA_STOP_THETA_DEG, 0.0)


def tilted_about_centre(eyes: EyeModel, tilt_h_deg: np.ndarray | float, tilt_v_deg: np.ndarray | float = 0.0,
                        pivot_depth: float = CORNEA_PIVOT_DEPTH_MM) -> EyeModel:
    """The cornea turned by a further (h nasal, v superior) deg about the point `pivot_depth` mm behind its apex
    on the axis (default: gkaModelEye's corneal ellipsoid centre), the apex moving with it. The angles add to
    the eye's own tilt (exact for an untilted cornea, a small-angle composition otherwise)."""
    h, v = (np.broadcast_to(np.radians(np.asarray(x, dtype=float)), eyes.shape) for x in (tilt_h_deg, tilt_v_deg))
    a = np.full(eyes.shape, float(pivot_depth))
    axis = np.stack([np.cos(v) * np.sin(h), np.sin(v), np.cos(v) * np.cos(h)], axis=-1)
    centre = np.stack([np.zeros_like(a), np.zeros_like(a), -a], axis=-1)
    offset = centre + a[..., None] * axis  # the turned apex
    return eyes.replace(cornea_offset=eyes.cornea_offset + offset,
                        cornea_tilt_deg=eyes.cornea_tilt_deg + np.stack([np.degrees(h), np.degrees(v)], axis=-1))


def conditional_astigmatism(eyes: EyeModel, rng: np.random.Generator | np.ndarray) -> tuple[np.ndarray, ...]:
    """(anterior J0, J45, posterior J0, J45) in D per eye, drawn from the Rozema 2011 normal given the eye's
    other parameters (module docstring); `rng` may instead be the standard normal deviates (E, 4) to use."""
    e = eyes.as_batch()
    observed = {
        "K_ant_M": 337.2 / e.anterior_mean_radius,
        "K_post_M": (1337.2 - 1378.0) / e.posterior_mean_radius,
        "R_lens_ant": e.lens_anterior_radius,
        "R_lens_post": -e.lens_posterior_radius,
        "lens_thickness": e.lens_thickness,
        "CCT": e.cct,
        "ACD": e.acd,
        "axial_length": e.axial_length,
        "pupil_diameter_scotopic": 2.0 * e.pupil_radius,
    }
    mean, cov = rozema2011().conditional(observed, ASTIGMATISM_NAMES)
    w, v = np.linalg.eigh(cov)
    z = rng.standard_normal(mean.shape) if isinstance(rng, np.random.Generator) else np.asarray(rng, dtype=float)
    draws = mean + z @ (v * np.sqrt(np.clip(w, 0.0, None))).T
    return tuple(draws[:, i] for i in range(len(ASTIGMATISM_NAMES)))


def full_anatomy(
    eyes: EyeModel,
    rng: np.random.Generator,
    *,
    astigmatism: bool = True,
    decentration: bool = True,
    stop: bool = True,
    tilt: bool = True,
) -> EyeModel:
    """`eyes` (a batch, anatomy as right eyes) with the anatomy of the module docstring added. Every deviate is
    drawn from `rng` whatever is switched on (astigmatism (E, 4), then decentration (E, 2) and its shift with size
    (E, 2)), so each component of the same generator state is the same with or without the others."""
    e = eyes.as_batch()
    n = len(e)
    z_astigmatism, z_decentre, z_shift = (rng.standard_normal((n, k)) for k in (4, 2, 2))
    if astigmatism:
        e = with_power_vectors(e, *conditional_astigmatism(e, z_astigmatism))
    if decentration:
        at_4mm = PUPIL_DECENTRE_MEAN_MM + PUPIL_DECENTRE_SD_MM * z_decentre
        shift = PUPIL_SHIFT_MEAN_MM_PER_MM + PUPIL_SHIFT_SD_MM_PER_MM * z_shift
        change = 2.0 * e.pupil_radius - PUPIL_REFERENCE_DIAMETER_MM
        e = e.replace(pupil_decentre=e.pupil_decentre + at_4mm + change[:, None] * shift, pupil_shift_per_mm=shift)
    if stop:
        eccentricity, axis = gka_stop(e.pupil_radius)
        e = e.replace(pupil_eccentricity=eccentricity, pupil_axis_deg=axis)
    if tilt:
        e = tilted_about_centre(e, CORNEA_TILT_DEG, 0.0)
    return e
