"""Component-wise (x, y, z as separate arrays) ray traces through the cornea, conic or biconic.

The pupil solve traces about 8 rays per boundary point (Broyden's method, `newton.secant2d`), so
`trace_into_eye` is the forward model's hot loop. This module traces the same ray on separate coordinate
arrays: no stacking into (..., 3), no einsum or `np.linalg.norm` per step, no intersection point built only
to test it.

- `trace_conic` (`Conic` surfaces) performs the same floating-point operations in the same order as
  `trace_into_eye` (anterior point and normal, `refract`, `Conic.intersect`, `Plane.intersect`): its results
  are bit for bit those of the general path (tests/test_solvers.py holds them equal).
- `trace_biconic` (`Biconic` surfaces, `BiconicPair`) traces each surface in its own frame: the anterior
  point, normal and refraction in the anterior's frame (where the source was moved once), the posterior's
  intersection (`Biconic.intersect`'s guide root and Newton), normal and refraction in the posterior's frame,
  and the pupil plane met there. Rotations are exact in real arithmetic, so it equals the general path to
  rounding (about 1e-13 mm; tests/test_toric_surface.py).

Frames and units as in `optics.pupil`: eye-local frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.biconic import MAX_NEWTON, SURFACE_TOLERANCE_MM, Biconic, guide_roots, sag
from eyehil.emulator.optics.conic import EPS_T, Conic, Plane, Vec, nearest_hit

#: the fraction of a batch still moving below which the posterior Newton iterates on those elements alone
STRAGGLERS = 0.1


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
    t1, ok2 = nearest_hit(posterior, a, d1)
    b = (a[0] + t1 * d1[0], a[1] + t1 * d1[1], a[2] + t1 * d1[2])
    d2, ok3 = _refract(d1, _normal(posterior, *b), eta2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t2 = (np.asarray(plane.z0) - b[2]) / d2[2]
    ok4 = np.isfinite(t2) & (t2 > EPS_T)
    t2 = np.where(ok4, t2, 0.0)
    return b[0] + t2 * d2[0], b[1] + t2 * d2[1], ok & ok1 & ok2 & ok3 & ok4


# --- biconic (toric) corneas ----------------------------------------------------------------------------
@dataclass(frozen=True)
class BiconicPair:
    """The anterior and posterior biconics and the pupil plane as component arrays, each broadcast to one
    batch shape (so that a subset of the batch is an index into every field; `take`).

    `m` (9 arrays, row-major) turns anterior-frame vectors into posterior-frame ones and `off` (3) is the
    anterior apex in the posterior frame; `plane_n` (3) is the eye's +z in the posterior frame and
    `plane_d` the pupil plane's signed height above the posterior apex along it; `back_x`, `back_y` (3 each)
    are the eye's x and y axes in the posterior frame and `back_v` the posterior apex (x, y, eye-local)."""

    front: tuple[np.ndarray, ...]  # c_x, c_y, (1 + Q_x) c_x^2, (1 + Q_y) c_y^2, aperture^2
    back: tuple[np.ndarray, ...]
    guide: tuple[np.ndarray, np.ndarray]  # the posterior's mean curvature c and mean 1 + Q
    m: tuple[np.ndarray, ...]
    off: tuple[np.ndarray, ...]
    plane_n: tuple[np.ndarray, ...]
    plane_d: np.ndarray
    back_x: tuple[np.ndarray, ...]
    back_y: tuple[np.ndarray, ...]
    back_v: tuple[np.ndarray, ...]

    @staticmethod
    def of(anterior: Biconic, posterior: Biconic, plane: Plane, shape: tuple[int, ...]) -> BiconicPair:
        """The pair of surfaces broadcast to the batch `shape`."""
        def b(v: np.ndarray) -> np.ndarray:
            return np.broadcast_to(np.asarray(v, dtype=float), shape)

        def shape_fields(s: Biconic) -> tuple[np.ndarray, ...]:
            cx, cy = 1.0 / s.radius_x, 1.0 / s.radius_y
            return tuple(b(v) for v in (cx, cy, (1.0 + s.conic_x) * cx * cx, (1.0 + s.conic_y) * cy * cy,
                                        s.aperture**2))

        ra, rp = anterior.rotation, posterior.rotation
        m = np.swapaxes(rp, -1, -2) @ ra
        off = np.einsum("...ji,...j->...i", rp, anterior.vertex - posterior.vertex)
        height = np.asarray(plane.z0, dtype=float) - posterior.vertex[..., 2]
        guide = (0.5 * (1.0 / posterior.radius_x + 1.0 / posterior.radius_y),
                 1.0 + 0.5 * (posterior.conic_x + posterior.conic_y))
        return BiconicPair(
            front=shape_fields(anterior), back=shape_fields(posterior), guide=(b(guide[0]), b(guide[1])),
            m=tuple(b(m[..., i, j]) for i in range(3) for j in range(3)),
            off=tuple(b(off[..., i]) for i in range(3)), plane_n=tuple(b(rp[..., 2, i]) for i in range(3)),
            plane_d=b(height), back_x=tuple(b(rp[..., 0, i]) for i in range(3)),
            back_y=tuple(b(rp[..., 1, i]) for i in range(3)),
            back_v=tuple(b(posterior.vertex[..., i]) for i in range(2)))

    def take(self, index: tuple[np.ndarray, ...]) -> BiconicPair:
        """The fields of the batch elements at `index` (a tuple of index arrays)."""
        return BiconicPair(*(tuple(v[index] for v in f) if isinstance(f, tuple) else f[index]
                             for f in (self.front, self.back, self.guide, self.m, self.off, self.plane_n,
                                       self.plane_d, self.back_x, self.back_y, self.back_v)))


def _biconic_hit(pair: BiconicPair, p: Vec, u: Vec, t: np.ndarray, ok: np.ndarray):
    """`Biconic._refine` in the posterior's frame from the root t: (t, hit, s_x, s_y at the hit).

    The hit is judged at the last iterate before the final step (below 1e-13 mm), whose sag the step used:
    its residual |f| is below 1e-13 |f'| mm, and its normal and cap test differ from those at the final t by
    about 1e-13 (no extra sag evaluation). Once at most `STRAGGLERS` of the elements still take steps of
    1e-13 mm or more, only those are iterated on (from a warm start a third of the elements take a second
    step and a twentieth a third)."""
    px, py, pz = p
    ux, uy, uz = u
    t = np.where(ok, t, 0.0)
    for _ in range(MAX_NEWTON):
        x, y = px + t * ux, py + t * uy
        s, disc, sx, sy = sag(*pair.back[:4], x, y)
        f = -(pz + t * uz) - s
        with np.errstate(divide="ignore", invalid="ignore"):
            dt = np.where(ok, f / (-uz - sx * ux - sy * uy), 0.0)
        dt = np.where(np.isfinite(dt), dt, 0.0)
        t = t - dt
        moving = np.abs(dt) >= 1e-13
        count = np.count_nonzero(moving)
        if count == 0:
            break
        if count <= STRAGGLERS * moving.size and t.shape == x.shape == disc.shape:
            _finish_stragglers(pair, p, u, np.nonzero(moving), t, (x, y, disc, f, sx, sy))
            break
    inside = (disc > 0) & (x * x + y * y <= pair.back[4])
    return t, ok & inside & (np.abs(f) <= SURFACE_TOLERANCE_MM) & (t > EPS_T), sx, sy


def _finish_stragglers(pair: BiconicPair, p: Vec, u: Vec, index: tuple[np.ndarray, ...], t: np.ndarray,
                       last: tuple[np.ndarray, ...]) -> None:
    """`_biconic_hit`'s remaining steps for the elements at `index` only, written into t and the last iterate's
    (x, y, disc, f, s_x, s_y) in place."""
    shape = t.shape
    ray = [np.broadcast_to(v, shape)[index] for v in (*p, *u, *pair.back[:4])]  # px py pz ux uy uz, 4 shape
    ti = t[index]
    for _ in range(MAX_NEWTON):
        px, py, pz, ux, uy, uz, *back = ray
        x, y = px + ti * ux, py + ti * uy
        s, disc, sx, sy = sag(*back, x, y)
        f = -(pz + ti * uz) - s
        with np.errstate(divide="ignore", invalid="ignore"):
            dt = f / (-uz - sx * ux - sy * uy)  # these elements moved, so they are ok
        dt = np.where(np.isfinite(dt), dt, 0.0)
        ti = ti - dt
        for whole, part in zip(last, (x, y, disc, f, sx, sy), strict=True):
            whole[index] = part
        t[index] = ti
        still = np.abs(dt) >= 1e-13
        if not still.any():
            return
        index = tuple(i[still] for i in index)
        ray, ti = [v[still] for v in ray], ti[still]


def _posterior_hit(pair: BiconicPair, p: Vec, u: Vec, start: np.ndarray | None):
    """`Biconic.intersect` in the posterior's frame: (t (NaN where there is no hit), hit, s_x, s_y at the hit).

    Cold (`start` None or NaN): the guide's near root, then its far root where the near one does not end on
    the cap. Warm (`start` finite, a neighbouring ray's t): Newton from there, and the cold way where that
    fails."""
    if start is None:
        near, far, any_root = guide_roots(*pair.guide, p, u)
        t, hit, sx, sy = _biconic_hit(pair, p, u, near, any_root)
        i = np.nonzero(~hit & any_root)
        if i[0].size:
            t2, hit2, sx2, sy2 = _biconic_hit(pair.take(i), tuple(v[i] for v in p), tuple(v[i] for v in u), far[i],
                                              np.ones(i[0].size, dtype=bool))
            t, hit, sx, sy = _put((t, hit, sx, sy), i, (np.where(hit2, t2, t[i]), hit2, sx2, sy2))
        return np.where(hit, t, np.nan), hit, sx, sy
    warm = np.isfinite(start)
    t, hit, sx, sy = _biconic_hit(pair, p, u, np.where(warm, start, 0.0), warm)
    i = np.nonzero(~hit)
    if i[0].size:
        part = _posterior_hit(pair.take(i), tuple(v[i] for v in p), tuple(v[i] for v in u), None)
        t, hit, sx, sy = _put((t, hit, sx, sy), i, part)
    return np.where(hit, t, np.nan), hit, sx, sy


def _put(arrays: tuple[np.ndarray, ...], index: tuple[np.ndarray, ...], parts: tuple[np.ndarray, ...]):
    """Copies of `arrays` with `parts` written at `index`."""
    out = tuple(a.copy() for a in arrays)
    for a, part in zip(out, parts, strict=True):
        a[index] = part
    return out


def trace_biconic(pair: BiconicPair, eta1: np.ndarray, eta2: np.ndarray, qx: np.ndarray, qy: np.ndarray,
                  source: Vec, start: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """`pupil.trace_into_eye` from `source` for biconic surfaces: (x, y) on the pupil plane (eye-local), valid,
    and the ray's parameter t at the posterior (NaN where it misses; `start` for a neighbouring ray, see
    `_posterior_hit`).

    `source` is given in the ANTERIOR surface's frame; q = (qx, qy) are the anterior surface coordinates."""
    s, disc, sx, sy = sag(*pair.front[:4], qx, qy)
    ok = (disc > 0) & (qx * qx + qy * qy <= pair.front[4])
    norm = np.sqrt(sx * sx + sy * sy + 1.0)
    na = (sx / norm, sy / norm, 1.0 / norm)
    a = (qx, qy, -s)
    d0 = _unit(a[0] - source[0], a[1] - source[1], a[2] - source[2])
    ok &= _dot(na, d0) < 0
    d1, ok1 = _refract(d0, na, eta1)
    m = pair.m
    ap = tuple(m[3 * i] * a[0] + m[3 * i + 1] * a[1] + m[3 * i + 2] * a[2] + pair.off[i] for i in range(3))
    up = tuple(m[3 * i] * d1[0] + m[3 * i + 1] * d1[1] + m[3 * i + 2] * d1[2] for i in range(3))
    t1, hit, bsx, bsy = _posterior_hit(pair, ap, up, start)
    t, bsx, bsy = np.where(hit, t1, 0.0), np.where(hit, bsx, 0.0), np.where(hit, bsy, 0.0)
    b = (ap[0] + t * up[0], ap[1] + t * up[1], ap[2] + t * up[2])
    norm = np.sqrt(bsx * bsx + bsy * bsy + 1.0)
    d2, ok3 = _refract(up, (bsx / norm, bsy / norm, 1.0 / norm), eta2)
    n = pair.plane_n
    with np.errstate(divide="ignore", invalid="ignore"):
        t2 = (pair.plane_d - (n[0] * b[0] + n[1] * b[1] + n[2] * b[2])) / (n[0] * d2[0] + n[1] * d2[1] + n[2] * d2[2])
    ok4 = np.isfinite(t2) & (t2 > EPS_T)
    t2 = np.where(ok4, t2, 0.0)
    p = (b[0] + t2 * d2[0], b[1] + t2 * d2[1], b[2] + t2 * d2[2])
    ex, ey = pair.back_x, pair.back_y
    x = ex[0] * p[0] + ex[1] * p[1] + ex[2] * p[2] + pair.back_v[0]
    y = ey[0] * p[0] + ey[1] * p[1] + ey[2] * p[2] + pair.back_v[1]
    return x, y, ok & ok1 & hit & ok3 & ok4, t1
