"""Eye rotation (Fick angles about separate centres, Listing's law) and the fixation solver.

Rotation of an eye (eye frame, mm): torsion about the optic (z) axis through the apex, then
elevation about the elevation centre, then azimuth about the azimuth centre, each X <- R (X - c) + c
(gkaModelEye, Aguirre 2019). Positive azimuth turns the eye toward +x (the subject's left; the pupil
moves right in the camera image), positive elevation toward +y (up). The composed pose is a rigid map
X -> A X + b. Listing's law adds the pseudo-torsion t = -asin(sin H sin V / (1 + cos V cos H)),
H = -azimuth, V = -elevation (primary position (0, 0)).

Line of sight: the ray through the centre of the entrance pupil that reaches the fovea. The fovea is
placed where the chief ray of a distant point at the fovea angles (alpha_h nasal, alpha_v superior; the
direction [cos v sin h, sin v, cos v cos h]) lands, so the line of sight in the eye-local frame is that
chief ray: it enters the anterior cornea at the point whose refracted ray crosses the stop centre, and
it is fixed to the eye. (gkaModelEye places the fovea by the nodal-point visual axis instead; the
difference is a fraction of a degree in alpha, which every gaze estimator calibrates away.)

Fixation: find (azimuth, elevation) with Listing torsion so that the rotated line of sight passes
through the target; a batched quasi-Newton (Broyden, `secant2d`) on the angular residual over all eyes x
targets, reported as the distance (mm) by which the line of sight misses the target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.surfaces import cornea_optics, lens_surfaces, pupil_centre, retina
from eyehil.emulator.optics.newton import secant2d
from eyehil.emulator.optics.pupil import trace_into_eye
from eyehil.emulator.optics.rays import _dot, distance_to_line, length, refract, unit

FIXATION_TOLERANCE_MM = 0.01


def listing_torsion(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """Pseudo-torsion (deg) that Listing's law adds to Fick angles (module docstring)."""
    h, v = -np.radians(azimuth_deg), -np.radians(elevation_deg)
    return -np.degrees(np.arcsin(np.sin(h) * np.sin(v) / (1.0 + np.cos(v) * np.cos(h))))


def _rotations(az: np.ndarray, el: np.ndarray, tor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched (..., 3, 3) rotations: torsion about z, elevation (+z toward +y), azimuth (+z toward +x); radians."""
    one, zero = np.ones_like(az), np.zeros_like(az)
    ct, st, ce, se, ca, sa = np.cos(tor), np.sin(tor), np.cos(el), np.sin(el), np.cos(az), np.sin(az)
    rt = np.stack([ct, -st, zero, st, ct, zero, zero, zero, one], axis=-1).reshape(*az.shape, 3, 3)
    re = np.stack([one, zero, zero, zero, ce, se, zero, -se, ce], axis=-1).reshape(*az.shape, 3, 3)
    ra = np.stack([ca, zero, sa, zero, one, zero, -sa, zero, ca], axis=-1).reshape(*az.shape, 3, 3)
    return rt, re, ra


def pose_transform(
    azimuth_centre: np.ndarray, elevation_centre: np.ndarray, az: np.ndarray, el: np.ndarray, tor: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(A (..., 3, 3), b (..., 3)) such that a rotated eye-frame point is A X + b; angles in radians."""
    rt, re, ra = _rotations(az, el, tor)
    a = ra @ re @ rt
    ce, ca = elevation_centre, azimuth_centre
    b_el = ce - np.einsum("...ij,...j->...i", re, ce)
    b = np.einsum("...ij,...j->...i", ra, b_el) + ca - np.einsum("...ij,...j->...i", ra, ca)
    return a, b


@dataclass(frozen=True)
class LineOfSight:
    """Per eye, eye-local frame: a point on the line of sight (its entry point on the anterior cornea),
    its outward unit direction, the fovea, and validity."""

    origin: np.ndarray
    direction: np.ndarray
    fovea: np.ndarray
    valid: np.ndarray


def line_of_sight(eye: EyeModel, media: Media) -> LineOfSight:
    """The line of sight of each eye (module docstring), from the fovea angles, through the stop centre."""
    h, v = np.radians(eye.alpha_h) * eye.side_sign, np.radians(eye.alpha_v)
    outward = np.stack([np.cos(v) * np.sin(h), np.sin(v), np.cos(v) * np.cos(h)], axis=-1)
    optics = cornea_optics(eye, media)
    stop = pupil_centre(eye)

    def residual(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, ok = trace_into_eye(optics, q, direction=-outward)
        return p[..., :2] - stop[..., :2], ok

    sol = secant2d(residual, stop[..., :2] - 3.0 * outward[..., :2], max_step=0.5, subset=False)
    entry, _ = optics.anterior.point(sol.q)
    fovea, reached = _trace_to_retina(eye, media, optics, entry, -outward)
    valid = sol.ok & (length(sol.residual) < 1e-6)
    return LineOfSight(origin=entry, direction=outward, fovea=fovea, valid=valid & reached)


def _trace_to_retina(eye: EyeModel, media: Media, optics, entry: np.ndarray, d0: np.ndarray):
    """Continue the chief ray through cornea, aqueous and lens to the retina (ground truth fovea)."""
    d1, ok = refract(d0, optics.anterior.normal(entry), media.air, media.cornea)
    t, ok1 = optics.posterior.intersect(entry, d1)
    p = entry + np.nan_to_num(t)[..., None] * d1
    d, ok2 = refract(d1, optics.posterior.normal(p), media.cornea, media.aqueous)
    ok &= ok1 & ok2
    indices = ((media.aqueous, eye.lens_index), (eye.lens_index, media.vitreous))
    for surface, (n1, n2) in zip(lens_surfaces(eye), indices, strict=True):
        t, hit = surface.intersect(p, d)
        p = p + np.nan_to_num(t)[..., None] * d
        d, bent = refract(d, surface.normal(p), n1, n2)
        ok &= hit & bent
    centre, axes = retina(eye)
    return p + _ellipsoid_far_hit(p - centre, d, axes)[..., None] * d, ok


def _ellipsoid_far_hit(p: np.ndarray, d: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Largest t with |(p + t d) / axes| = 1 (the ray leaving the inside of the ellipsoid)."""
    ps, ds = p / axes, d / axes
    a, b, c = _dot(ds, ds), 2 * _dot(ps, ds), _dot(ps, ps) - 1
    return (-b + np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))) / (2 * a)


@dataclass(frozen=True)
class Pose:
    """Eye poses (deg) and how well each fixation converged (miss distance, mm)."""

    azimuth: np.ndarray
    elevation: np.ndarray
    torsion: np.ndarray
    residual_mm: np.ndarray
    valid: np.ndarray


def eye_centres(eye: EyeModel) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) rotation centres in each eye's own frame (left eyes mirrored)."""
    return eye.frame_vector(eye.azimuth_centre), eye.frame_vector(eye.elevation_centre)


def posed(eye_c: tuple[np.ndarray, np.ndarray], az_deg, el_deg, tor_deg) -> tuple[np.ndarray, np.ndarray]:
    """pose_transform with angles in degrees and the centres of `eye_centres`."""
    return pose_transform(eye_c[0], eye_c[1], np.radians(az_deg), np.radians(el_deg), np.radians(tor_deg))


def solve_fixation(
    centres: tuple[np.ndarray, np.ndarray], los: LineOfSight, targets: np.ndarray, listing: bool = True
) -> Pose:
    """Poses that put each line of sight through its target.

    `centres` and `los` fields broadcast against `targets` (..., 3), all in the eye frame (the target
    relative to this eye's unrotated apex, mm)."""
    full = np.broadcast_shapes(targets.shape, centres[0].shape, centres[1].shape, los.origin.shape)
    targets = np.broadcast_to(targets, full)
    centres = tuple(np.broadcast_to(c, full) for c in centres)
    shape = full[:-1]
    origin, direction = (np.broadcast_to(v, targets.shape) for v in (los.origin, los.direction))
    gaze = unit(targets - centres[0])
    e1 = unit(np.cross(np.array([0.0, 1.0, 0.0]), gaze))
    e2 = np.cross(gaze, e1)

    def rotated(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tor = listing_torsion(q[..., 0], q[..., 1]) if listing else np.zeros(shape)
        a, b = posed(centres, q[..., 0], q[..., 1], tor)
        return np.einsum("...ij,...j->...i", a, origin) + b, np.einsum("...ij,...j->...i", a, direction)

    def residual(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, d = rotated(q)
        miss = unit(targets - p) - d
        return np.stack([_dot(miss, e1), _dot(miss, e2)], axis=-1), np.ones(shape, dtype=bool)

    in_front = gaze[..., 2] > 0
    h0 = np.degrees(np.arctan2(gaze[..., 0], gaze[..., 2]) - np.arctan2(direction[..., 0], direction[..., 2]))
    v0 = np.degrees(np.arcsin(gaze[..., 1]) - np.arcsin(direction[..., 1]))
    sol = secant2d(residual, np.stack([h0, v0], axis=-1), h=1e-6, tol=1e-10, max_step=10.0, subset=False)
    p, d = rotated(sol.q)
    miss = distance_to_line(targets, p, d)
    torsion = listing_torsion(sol.q[..., 0], sol.q[..., 1]) if listing else np.zeros(shape)
    valid = sol.ok & in_front & (miss <= FIXATION_TOLERANCE_MM) & np.broadcast_to(los.valid, shape)
    return Pose(azimuth=sol.q[..., 0], elevation=sol.q[..., 1], torsion=torsion, residual_mm=miss, valid=valid)
