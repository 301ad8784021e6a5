"""Biconic (toric) surfaces: two principal radii and a conic constant per principal meridian, placed
anywhere in the eye-local frame (apex offset, principal-meridian angle, tilt), and ray intersection.

Surface frame (x', y', z'): origin at the apex, z' along the surface axis (out of the eye), x' along the
first principal meridian. A point (x', y', z') lies on the surface where z' = -s(x', y') with the sag
(the biconic of optical design programs, e.g. Zemax "Biconic")

    s = (c_x x'^2 + c_y y'^2) / (1 + sqrt(1 - k_x c_x^2 x'^2 - k_y c_y^2 y'^2)),

c = 1 / R (vertex curvature of a principal meridian), k = 1 + Q (Q = -e^2). In each principal meridian
this is the conic of `conic.py` with (R, Q); equal radii and conic constants give that conic of
revolution. With (1 + Q_x) / R_x = (1 + Q_y) / R_y it is a tri-axial ellipsoid (gkaModelEye's and
Navarro 2006's canonical cornea). The outward normal is the gradient of z' + s: (s_x, s_y, 1) / |.|, so
it points out of the eye (+z') at the apex for R > 0; only R > 0 (surfaces bulging toward +z, the
cornea) is supported.

Placement: `vertex` (..., 3) is the apex in the eye-local frame and `rotation` (..., 3, 3) has the
surface axes x', y', z' as columns, so p_local = rotation (p' ) + vertex. The cap is the sheet that
contains the apex (the sag formula chooses it) within `aperture` of the surface axis (x'^2 + y'^2).

Intersection has no closed form (the biconic is a quartic): start from the closed-form root of the
quadric of revolution with the mean curvature and mean k, then Newton on f(t) = -z'(t) - s(x'(t), y'(t)),
f'(t) = -u_z' - s_x u_x' - s_y u_y', until every step is below 1e-13 mm (at most `MAX_NEWTON` steps);
a hit needs |f| <= 1e-10 mm. Known answer: equal radii and conics give the conic's root to 1e-12 mm.

Arrays broadcast: surface fields (...) against points (..., 3). Lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.conic import EPS_T

MAX_NEWTON = 12
SURFACE_TOLERANCE_MM = 1e-10


def rotation_matrix(axis_deg: np.ndarray, tilt_h_deg: np.ndarray, tilt_v_deg: np.ndarray) -> np.ndarray:
    """(..., 3, 3) with columns x', y', z': the meridian angle `axis_deg` about z (from +x toward +y), then
    the tilt that turns the axis +z to (cos v sin h, sin v, cos v cos h) (h toward +x, v toward +y)."""
    a, h, v = (np.radians(np.asarray(x, dtype=float)) for x in (axis_deg, tilt_h_deg, tilt_v_deg))
    a, h, v = np.broadcast_arrays(a, h, v)
    ca, sa, ch, sh, cv, sv = np.cos(a), np.sin(a), np.cos(h), np.sin(h), np.cos(v), np.sin(v)
    one, zero = np.ones_like(a), np.zeros_like(a)
    rz = np.stack([ca, -sa, zero, sa, ca, zero, zero, zero, one], axis=-1).reshape(*a.shape, 3, 3)
    rx = np.stack([one, zero, zero, zero, cv, -sv, zero, sv, cv], axis=-1).reshape(*a.shape, 3, 3)  # +z -> +y
    ry = np.stack([ch, zero, sh, zero, one, zero, -sh, zero, ch], axis=-1).reshape(*a.shape, 3, 3)  # +z -> +x
    return ry @ rx @ rz


def sag(cx: np.ndarray, cy: np.ndarray, kx: np.ndarray, ky: np.ndarray, x: np.ndarray, y: np.ndarray,
        gradient: bool = True) -> tuple[np.ndarray, ...]:
    """The sag s of the module docstring at surface coordinates (x, y), the argument of its root (> 0 where the
    sag exists) and, if `gradient`, its slopes s_x, s_y; per principal meridian c = 1 / R and k = (1 + Q) c^2."""
    x2, y2 = x * x, y * y
    s_num = cx * x2 + cy * y2
    disc = 1.0 - kx * x2 - ky * y2
    d = np.sqrt(np.maximum(disc, 1e-300))
    one_d = 1.0 + d
    if not gradient:
        return s_num / one_d, disc
    common = s_num / (d * one_d * one_d)
    return s_num / one_d, disc, x * (2.0 * cx / one_d + common * kx), y * (2.0 * cy / one_d + common * ky)


def guide_roots(c: np.ndarray, k: np.ndarray, p: tuple[np.ndarray, ...], u: tuple[np.ndarray, ...]):
    """(near, far) positive t of the ray p + t u (surface frame, component arrays) on the quadric of revolution
    of vertex curvature c and 1 + Q = k, x^2 + y^2 + k w^2 - 2 w / c = 0 (w = -z), and whether there is any."""
    px, py, pz = p
    ux, uy, uz = u
    # multiplied by c: c (x^2 + y^2) + c k w^2 - 2 w, with w = -(pz + t uz)
    a = c * (ux * ux + uy * uy + k * uz * uz)
    b = 2.0 * (c * (px * ux + py * uy + k * pz * uz) + uz)
    cc = c * (px * px + py * py + k * pz * pz) + 2.0 * pz
    disc = b * b - 4.0 * a * cc
    sq = np.sqrt(np.maximum(disc, 0.0))
    q = -0.5 * (b + np.where(b >= 0, sq, -sq))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1, r2 = q / a, cc / q
    lo, hi = np.minimum(r1, r2), np.maximum(r1, r2)
    near = np.where(lo > EPS_T, lo, hi)
    ok = (disc >= 0) & np.isfinite(near) & (near > EPS_T)
    return near, np.where(np.isfinite(hi), hi, near), ok


@dataclass(frozen=True, eq=False)
class Biconic:
    """A biconic cap (see the module docstring): apex `vertex` (..., 3), axes `rotation` (..., 3, 3),
    principal radii and conic constants (...) and the aperture radius (...), mm."""

    vertex: np.ndarray
    rotation: np.ndarray
    radius_x: np.ndarray
    radius_y: np.ndarray
    conic_x: np.ndarray
    conic_y: np.ndarray
    aperture: np.ndarray

    def __post_init__(self) -> None:
        for name in ("vertex", "rotation", "radius_x", "radius_y", "conic_x", "conic_y", "aperture"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float))
        for name in ("radius_x", "radius_y"):
            value = getattr(self, name)
            if not np.all(np.isfinite(value)) or np.any(value <= 0):
                raise ValueError(f"Biconic.{name} must be finite and > 0 mm (a surface bulging toward +z)")
        if np.any(self.aperture <= 0):
            raise ValueError("Biconic.aperture must be > 0 mm")
        if self.vertex.shape[-1:] != (3,) or self.rotation.shape[-2:] != (3, 3):
            raise ValueError("Biconic.vertex must be (..., 3) and rotation (..., 3, 3)")

    def reshaped(self, extra_dims: int) -> Biconic:
        """The same surfaces with `extra_dims` singleton axes before the vector axes, to broadcast."""
        pad = (1,) * extra_dims

        def r(a: np.ndarray, tail: int) -> np.ndarray:
            return a.reshape(a.shape[: a.ndim - tail] + pad + a.shape[a.ndim - tail:])

        return Biconic(r(self.vertex, 1), r(self.rotation, 2), r(self.radius_x, 0), r(self.radius_y, 0),
                       r(self.conic_x, 0), r(self.conic_y, 0), r(self.aperture, 0))

    # --- frames ------------------------------------------------------------------------------------
    def _to_surface(self, v: np.ndarray, point: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = v - self.vertex if point else v
        m = self.rotation
        x = m[..., 0, 0] * d[..., 0] + m[..., 1, 0] * d[..., 1] + m[..., 2, 0] * d[..., 2]
        y = m[..., 0, 1] * d[..., 0] + m[..., 1, 1] * d[..., 1] + m[..., 2, 1] * d[..., 2]
        z = m[..., 0, 2] * d[..., 0] + m[..., 1, 2] * d[..., 1] + m[..., 2, 2] * d[..., 2]
        return x, y, z

    def _from_surface(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, point: bool = True) -> np.ndarray:
        m = self.rotation
        out = np.stack([m[..., i, 0] * x + m[..., i, 1] * y + m[..., i, 2] * z for i in range(3)], axis=-1)
        return out + self.vertex if point else out

    # --- shape ---------------------------------------------------------------------------------------
    def _sag(self, x: np.ndarray, y: np.ndarray, gradient: bool = False, check: bool = True):
        """Sag s (and whether it exists, unless `check` is False; and its gradient s_x, s_y if `gradient`)."""
        cx, cy = 1.0 / self.radius_x, 1.0 / self.radius_y
        s, disc, *slopes = sag(cx, cy, (1.0 + self.conic_x) * cx * cx, (1.0 + self.conic_y) * cy * cy, x, y,
                               gradient)
        valid = ((disc > 0) & (x * x + y * y <= self.aperture**2)) if check else None
        return (s, valid, *slopes)

    def mean_radius(self) -> np.ndarray:
        """Radius of the mean vertex curvature, 2 / (1/R_x + 1/R_y) (mm)."""
        return 2.0 / (1.0 / self.radius_x + 1.0 / self.radius_y)

    def osculating_sphere(self) -> tuple[np.ndarray, np.ndarray]:
        """(centre (..., 3), radius (...)) of the sphere of mean vertex curvature touching the apex."""
        r = self.mean_radius()
        zero = np.zeros_like(r)
        return self._from_surface(zero, zero, -r), r

    def point(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The surface point (..., 3, eye-local) at surface coordinates q = (x', y') (..., 2), and whether it exists."""
        s, valid = self._sag(q[..., 0], q[..., 1])
        return self._from_surface(q[..., 0], q[..., 1], -s), valid

    def point_normal(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`point(q)` and the unit outward normal there in one pass: (point (..., 3), normal (..., 3), valid)."""
        s, valid, sx, sy = self._sag(q[..., 0], q[..., 1], gradient=True)
        norm = np.sqrt(sx * sx + sy * sy + 1.0)
        point = self._from_surface(q[..., 0], q[..., 1], -s)
        return point, self._from_surface(sx / norm, sy / norm, 1.0 / norm, point=False), valid

    def coords(self, p: np.ndarray) -> np.ndarray:
        """Surface coordinates (x', y') (..., 2) of eye-local points p (..., 3) (their foot on the x'y' plane)."""
        x, y, _ = self._to_surface(p)
        return np.stack([x, y], axis=-1)

    def in_surface_frame(self, p: np.ndarray) -> np.ndarray:
        """Eye-local points p (..., 3) in the surface frame (x', y', z') (..., 3)."""
        return np.stack(self._to_surface(p), axis=-1)

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normal (..., 3, eye-local) at surface points p."""
        x, y, _ = self._to_surface(p)
        _, _, sx, sy = self._sag(x, y, gradient=True)
        norm = np.sqrt(sx * sx + sy * sy + 1.0)
        return self._from_surface(sx / norm, sy / norm, 1.0 / norm, point=False)

    def on_cap(self, p: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Whether eye-local points p lie on the cap (within `tol` mm along the axis)."""
        x, y, z = self._to_surface(p)
        s, valid = self._sag(x, y)
        return valid & (np.abs(z + s) <= tol)

    def intersect(self, p: np.ndarray, u: np.ndarray, far: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Ray p + t u (u unit, eye-local) meets the cap: (t, valid); the nearest t > 0, or the farthest if `far`.

        The guide is the quadric of revolution with the mean curvature and mean k, without its cap and aperture
        (the sag picks the apex sheet); its other root is refined too where the first does not end on the cap."""
        ray = self._to_surface(p) + self._to_surface(u, point=False)
        t_near, t_far, ok = self._guide_roots(ray)
        t, valid = self._refine(ray, t_far if far else t_near, ok)
        if np.any(~valid):
            t2, valid2 = self._refine(ray, t_near if far else t_far, ok)
            use = ~valid & valid2
            t, valid = np.where(use, t2, t), valid | use
        return np.where(valid, t, np.nan), valid

    def guide_intersect(self, p: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ray p + t u (eye-local) on the guide quadric alone (mean curvature and mean k, no cap): (nearest
        t > 0, whether there is one). Within a few micrometres of `intersect` for corneal toricity, at a fraction
        of its cost: a starting point, not a surface point."""
        t, _, ok = self._guide_roots(self._to_surface(p) + self._to_surface(u, point=False))
        return np.where(ok, t, np.nan), ok

    def _guide_roots(self, ray: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(near, far) positive roots of the mean quadric x^2 + y^2 + k w^2 - 2 R w = 0 (w = -z) and whether any."""
        c = 0.5 * (1.0 / self.radius_x + 1.0 / self.radius_y)
        return guide_roots(c, 1.0 + 0.5 * (self.conic_x + self.conic_y), ray[:3], ray[3:])

    def _refine(self, ray: tuple[np.ndarray, ...], t: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Newton on f(t) = -z'(t) - s(x'(t), y'(t)) from the guide root t (module docstring)."""
        px, py, pz, ux, uy, uz = ray
        t = np.where(ok, t, 0.0)
        for _ in range(MAX_NEWTON):
            s, _, sx, sy = self._sag(px + t * ux, py + t * uy, gradient=True, check=False)
            f = -(pz + t * uz) - s
            fp = -uz - sx * ux - sy * uy
            with np.errstate(divide="ignore", invalid="ignore"):
                dt = np.where(ok, f / fp, 0.0)
            dt = np.where(np.isfinite(dt), dt, 0.0)
            t = t - dt
            if np.max(np.abs(dt), initial=0.0) < 1e-13:
                break
        s, inside = self._sag(px + t * ux, py + t * uy)
        residual = np.abs(pz + t * uz + s)
        return t, ok & inside & (residual <= SURFACE_TOLERANCE_MM) & (t > EPS_T)
