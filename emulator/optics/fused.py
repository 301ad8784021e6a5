"""Component-wise (x, y, z as separate arrays) ray trace through a rotationally symmetric cornea.

The pupil solve traces about 16 rays per boundary point (a forward-difference Newton, `newton2d`), so
`trace_into_eye` is the forward model's hot loop. This module traces the same ray with the same
floating-point operations in the same order as `trace_into_eye` with `Conic` surfaces (anterior point and
normal, `refract`, `Conic.intersect`, `Plane.intersect`), but on separate coordinate arrays: no stacking
into (..., 3), no einsum or `np.linalg.norm` per step, no intersection point built only to test it. The
results are bit for bit those of the general path (tests/test_solvers.py holds them equal); biconic
(toric) corneas keep the general path.

Frames and units as in `optics.pupil`: eye-local frame, mm.
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.optics.conic import EPS_T, Conic, Plane

Vec = tuple[np.ndarray, np.ndarray, np.ndarray]


def _unit(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> Vec:
    s = np.sqrt(x * x + y * y + z * z)
    return x / s, y / s, z / s


def _dot(a: Vec, b: Vec) -> np.ndarray:
    """`rays._dot`: numpy's einsum adds the three products as (x + z) + y."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


def _normal(c: Conic, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> Vec:
    """`Conic.normal` at the surface point (x, y, z)."""
    return _unit(x, y, c.radius - (1.0 + c.conic) * (c.apex - z))


def _refract(d: Vec, n: Vec, eta: np.ndarray) -> tuple[Vec, np.ndarray]:
    """`rays.refract` with eta = n1 / n2."""
    cos_i = -_dot(n, d)
    flip = cos_i < 0
    n = tuple(np.where(flip, -c, c) for c in n)
    cos_i = np.abs(cos_i)
    k = 1.0 - eta**2 * (1.0 - cos_i**2)
    s = eta * cos_i - np.sqrt(np.maximum(k, 0.0))
    return (eta * d[0] + s * n[0], eta * d[1] + s * n[1], eta * d[2] + s * n[2]), k >= 0


def _intersect(c: Conic, p: Vec, u: Vec) -> tuple[np.ndarray, np.ndarray]:
    """`Conic.intersect` (nearest t > 0 on the cap): (t with 0 where there is no hit, valid)."""
    k = 1.0 + c.conic
    w0 = c.apex - p[2]
    a = u[0] ** 2 + u[1] ** 2 + k * u[2] ** 2
    b = 2.0 * (p[0] * u[0] + p[1] * u[1] - k * w0 * u[2] + c.radius * u[2])
    cc = p[0] ** 2 + p[1] ** 2 + k * w0**2 - 2.0 * c.radius * w0
    disc = b * b - 4.0 * a * cc
    sq = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (b + np.where(b >= 0, sq, -sq))
    with np.errstate(divide="ignore", invalid="ignore"):
        linear = np.abs(a) < 1e-14
        t1 = np.where(linear, -cc / b, q / a)
        t2 = np.where(linear, np.inf, cc / q)
    best = np.full(np.broadcast_shapes(a.shape, b.shape), np.inf)
    real = disc >= 0
    for t in (t1, t2):
        hit = real & np.isfinite(t) & (t > EPS_T)
        s = np.where(hit, t, 0.0)
        x, y, z = p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2]
        w_over_r = (c.apex - z) / c.radius
        cap = (w_over_r >= -1e-12) & ((k <= 0) | (w_over_r * k <= 1.0 + 1e-12))
        hit &= cap & (x**2 + y**2 <= c.aperture**2)
        best = np.where(hit & (t < best), t, best)
    valid = np.isfinite(best)
    return np.where(valid, best, 0.0), valid


def trace_conic(
    anterior: Conic, posterior: Conic, plane: Plane, eta1: np.ndarray, eta2: np.ndarray,
    qx: np.ndarray, qy: np.ndarray, source: Vec,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`pupil.trace_into_eye` from the point `source` for conic surfaces: (x, y) on the pupil plane, valid.

    eta1 = n_air / n_cornea, eta2 = n_cornea / n_aqueous; q = (qx, qy) the anterior surface coordinates."""
    r2 = qx**2 + qy**2
    k = 1.0 + anterior.conic
    disc = 1.0 - k * r2 / anterior.radius**2
    ok = (disc >= 0) & (r2 <= anterior.aperture**2)
    a = (qx, qy, anterior.apex - r2 / (anterior.radius * (1.0 + np.sqrt(np.maximum(disc, 0.0)))))
    na = _normal(anterior, *a)
    d0 = _unit(a[0] - source[0], a[1] - source[1], a[2] - source[2])
    ok &= _dot(na, d0) < 0
    d1, ok1 = _refract(d0, na, eta1)
    t1, ok2 = _intersect(posterior, a, d1)
    b = (a[0] + t1 * d1[0], a[1] + t1 * d1[1], a[2] + t1 * d1[2])
    d2, ok3 = _refract(d1, _normal(posterior, *b), eta2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t2 = (np.asarray(plane.z0) - b[2]) / d2[2]
    ok4 = np.isfinite(t2) & (t2 > EPS_T)
    t2 = np.where(ok4, t2, 0.0)
    return b[0] + t2 * d2[0], b[1] + t2 * d2[1], ok & ok1 & ok2 & ok3 & ok4
