"""Conic surfaces of revolution about the z axis of the eye-local frame, and ray intersection.

A surface with apex at z = z0, vertex radius R and conic constant Q (Q = -e^2: sphere 0, prolate
ellipsoid -1 < Q < 0, paraboloid -1, hyperboloid < -1) is, with depth w = z0 - z,

    F(x, y, z) = x^2 + y^2 + (1 + Q) w^2 - 2 R w = 0,

sag w(r) = r^2 / (R (1 + sqrt(1 - (1 + Q) r^2 / R^2))). R > 0 bulges toward +z (the cornea, the
front of the lens), R < 0 toward -z (the back of the lens). The gradient gives the normal
n ~ (x, y, R - (1 + Q) w): at the apex (0, 0, R), so for R > 0 it points out of the eye (+z).

Only the sheet half that contains the apex is the optical surface ("cap"): 0 <= w / R and, for an
ellipsoid, w / R <= 1 / (1 + Q); a surface also ends at its `aperture` radius (mm).

A ray p + t u meets the surface where a t^2 + b t + c = 0 with
a = ux^2 + uy^2 + (1+Q) uz^2, b = 2 (px ux + py uy) - 2 (1+Q) w0 uz + 2 R uz,
c = px^2 + py^2 + (1+Q) w0^2 - 2 R w0, w0 = z0 - pz.
Known answer (sphere, R = 10, apex 0, ray from (0, 0, 5) along -z): t = 5 (the apex).

Arrays broadcast: surface fields (...) against points (..., 3). Lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.rays import length

EPS_T = 1e-9  # mm: a ray does not meet the surface it starts on
Vec = tuple[np.ndarray, np.ndarray, np.ndarray]  # x, y, z as separate arrays


@dataclass(frozen=True, eq=False)
class Conic:
    """A conic of revolution about z (apex z0, vertex radius R, conic constant Q, aperture radius)."""

    apex: np.ndarray
    radius: np.ndarray
    conic: np.ndarray
    aperture: np.ndarray

    def __post_init__(self) -> None:
        for name in ("apex", "radius", "conic", "aperture"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        if np.any(self.radius == 0) or not np.all(np.isfinite(self.radius)):
            raise ValueError("Conic.radius must be finite and non-zero (mm)")
        if np.any(self.aperture <= 0):
            raise ValueError("Conic.aperture must be > 0 mm")

    def reshaped(self, extra_dims: int) -> Conic:
        """The same surfaces with `extra_dims` trailing singleton axes, to broadcast over a batch."""
        pad = (1,) * extra_dims
        return Conic(*(np.reshape(getattr(self, k), np.shape(getattr(self, k)) + pad)
                       for k in ("apex", "radius", "conic", "aperture")))

    def sag(self, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Depth w below the apex at squared radius r2 (mm^2); valid where the sag exists."""
        k = 1.0 + self.conic
        disc = 1.0 - k * r2 / self.radius**2
        valid = (disc >= 0) & (r2 <= self.aperture**2)
        w = r2 / (self.radius * (1.0 + np.sqrt(np.maximum(disc, 0.0))))
        return w, valid

    def point(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The surface point (..., 3) above (x, y) (..., 2), and whether it exists."""
        w, valid = self.sag(np.sum(xy**2, axis=-1))
        return np.concatenate([xy, (self.apex - w)[..., None]], axis=-1), valid

    def point_normal(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`point(q)` and `normal` there: (point (..., 3), unit normal (..., 3), valid)."""
        p, valid = self.point(q)
        return p, self.normal(p), valid

    def coords(self, p: np.ndarray) -> np.ndarray:
        """The surface coordinates (x, y) (..., 2) of points p (..., 3): the argument of `point`."""
        return p[..., :2]

    def osculating_sphere(self) -> tuple[np.ndarray, np.ndarray]:
        """(centre (..., 3), radius (...)) of the sphere of the vertex curvature touching the apex."""
        return np.stack(np.broadcast_arrays(0.0, 0.0, self.apex - self.radius), axis=-1), self.radius

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Unit normal (..., 3) at surface points p; +z at the apex when R > 0."""
        w = self.apex - p[..., 2]
        n = np.stack([p[..., 0], p[..., 1], self.radius - (1.0 + self.conic) * w], axis=-1)
        return n / length(n)[..., None]

    def on_cap(self, p: np.ndarray) -> np.ndarray:
        """Whether points p lie on the optical part of the surface (cap and aperture)."""
        w_over_r = (self.apex - p[..., 2]) / self.radius
        k = 1.0 + self.conic
        cap = (w_over_r >= -1e-12) & ((k <= 0) | (w_over_r * k <= 1.0 + 1e-12))
        return cap & (p[..., 0] ** 2 + p[..., 1] ** 2 <= self.aperture**2)

    def intersect(self, p: np.ndarray, u: np.ndarray, far: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Ray p + t u (u unit) meets the cap: (t, valid); the nearest t > 0, or the farthest if `far`.

        The nearest is `nearest_hit` on the components (the same numbers, bit for bit, in less time)."""
        fields = (self.apex, self.radius, self.conic, self.aperture)
        scalar = np.broadcast_shapes(np.shape(p)[:-1], np.shape(u)[:-1], *map(np.shape, fields)) == ()
        p, u = (np.atleast_2d(v) if scalar else v for v in (p, u))
        pc, uc = (p[..., 0], p[..., 1], p[..., 2]), (u[..., 0], u[..., 1], u[..., 2])
        if not far:
            t, valid = nearest_hit(self, pc, uc)
            t = np.where(valid, t, np.nan)
            return (t[0], valid[0]) if scalar else (t, valid)
        disc, t1, t2 = _roots(self, pc, uc)
        best = np.full(disc.shape, -np.inf)
        for t in (t1, t2):
            hit = (disc >= 0) & np.isfinite(t) & (t > EPS_T)
            hit &= self.on_cap(p + np.where(hit, t, 0.0)[..., None] * u)
            best = np.where(hit & (t > best), t, best)
        valid = np.isfinite(best)
        best = np.where(valid, best, np.nan)
        return (best[0], valid[0]) if scalar else (best, valid)


def _roots(c: Conic, p: Vec, u: Vec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The discriminant and the two roots t of the module docstring's quadratic for the ray p + t u (components),
    in the numerically stable form (q = -(b + sign(b) sqrt(disc)) / 2, t = q / a and c / q)."""
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
    return disc, t1, t2


def nearest_hit(c: Conic, p: Vec, u: Vec) -> tuple[np.ndarray, np.ndarray]:
    """`Conic.intersect` (nearest t > 0 on the cap) on component arrays p = (x, y, z), u: (t, 0 where there is no
    hit; valid).

    The roots of the module docstring's quadratic and the cap test of `Conic.on_cap`, nearer root first: where the
    nearer root hits it is the answer, and only the other elements (rays that miss or meet the far sheet first)
    test the farther root. `fused.trace_conic` traces with it too."""
    disc, t1, t2 = _roots(c, p, u)
    with np.errstate(invalid="ignore"):
        near, far = np.fmin(t1, t2), np.fmax(t1, t2)  # a NaN root leaves the other in both
    real = disc >= 0
    shape = near.shape
    hit = _hits_cap(c, p, u, near, real)
    rest = np.nonzero(~hit & real)
    if rest[0].size:
        def pick(v):
            return np.broadcast_to(v, shape)[rest]

        sub = Conic(pick(c.apex), pick(c.radius), pick(c.conic), pick(c.aperture))
        far_hit = _hits_cap(sub, tuple(map(pick, p)), tuple(map(pick, u)), far[rest], np.ones(rest[0].size, bool))
        near = near.copy()
        near[rest] = np.where(far_hit, far[rest], near[rest])
        hit = hit.copy()
        hit[rest] = far_hit
    return np.where(hit, near, 0.0), hit


def _hits_cap(c: Conic, p: Vec, u: Vec, t: np.ndarray, real: np.ndarray) -> np.ndarray:
    """Whether the root t (> EPS_T, finite, of a real pair) lands on the cap within the aperture."""
    k = 1.0 + c.conic
    hit = real & np.isfinite(t) & (t > EPS_T)
    s = np.where(hit, t, 0.0)
    x, y, z = p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2]
    w_over_r = (c.apex - z) / c.radius
    cap = (w_over_r >= -1e-12) & ((k <= 0) | (w_over_r * k <= 1.0 + 1e-12))
    return hit & cap & (x**2 + y**2 <= c.aperture**2)


@dataclass(frozen=True, eq=False)
class Plane:
    """The plane z = z0 (the pupil plane), within `aperture` of the axis."""

    z0: np.ndarray

    def intersect(self, p: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t, valid) for the ray p + t u, t > 0."""
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (np.asarray(self.z0) - p[..., 2]) / u[..., 2]
        valid = np.isfinite(t) & (t > EPS_T)
        return np.where(valid, t, np.nan), valid
