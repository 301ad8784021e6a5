"""The apparent pupil: boundary points of the aperture stop seen through the cornea.

Each boundary point P (on the pupil plane z = -(CCT + ACD), eye-local frame, mm) is imaged by the
one ray that leaves P, refracts at the posterior and then the anterior cornea, and passes through
the camera's nodal point O. Light paths are reversible, so the solver traces backwards: it takes the
exit point A = (x, y, sag) on the anterior cornea as the unknown, sends the ray O -> A into the eye
(refract air -> cornea at A, cornea -> aqueous at the posterior surface), meets the pupil plane at
P', and drives P' - P to zero with a 2 x 2 quasi-Newton iteration (`secant2d`; `solve_exit_points`).
The image of P is then the camera projection of A (the ray A -> O passes through the nodal point).

A boundary point is blocked (invalid) when its exit point falls beyond the limbus, the anterior
surface faces away from the camera, the ray misses the posterior cornea, or it is totally internally
reflected.

Known answer (paraxial): a single refracting surface of radius 7.8 mm and index 1.3375 images a pupil
3.6 mm deep at the entrance pupil of a paraxial ray trace, magnification and depth within 1%.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.biconic import Biconic
from eyehil.emulator.optics.conic import Conic, Plane
from eyehil.emulator.optics.fused import BiconicPair, trace_biconic, trace_conic
from eyehil.emulator.optics.newton import difference_jacobian, newton2d, secant2d
from eyehil.emulator.optics.rays import _dot, length, refract, unit

PUPIL_TOLERANCE_MM = 1e-6


@dataclass(frozen=True)
class CorneaOptics:
    """The cornea and pupil plane of one eye or a batch (eye-local frame, mm) and the indices."""

    anterior: Conic | Biconic
    posterior: Conic | Biconic
    pupil_plane: Plane
    n_air: np.ndarray
    n_cornea: np.ndarray
    n_aqueous: np.ndarray


@dataclass(frozen=True)
class ExitPoints:
    """Exit points (..., 3) on the anterior cornea, residual (mm) on the pupil plane, validity."""

    point: np.ndarray
    residual_mm: np.ndarray
    valid: np.ndarray


def trace_into_eye(
    optics: CorneaOptics, q: np.ndarray, *, source: np.ndarray | None = None, direction: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Where a ray entering the anterior cornea at the point above q (..., 2) meets the pupil plane.

    The ray comes from the point `source` (..., 3) or travels along the unit `direction` (..., 3)."""
    a, na, ok = optics.anterior.point_normal(q)
    d0 = unit(a - source) if direction is None else direction
    ok &= _dot(na, d0) < 0
    d1, ok1 = refract(d0, na, optics.n_air, optics.n_cornea)
    t1, ok2 = optics.posterior.intersect(a, d1)
    b = a + np.nan_to_num(t1)[..., None] * d1
    d2, ok3 = refract(d1, optics.posterior.normal(b), optics.n_cornea, optics.n_aqueous)
    t2, ok4 = optics.pupil_plane.intersect(b, d2)
    p = b + np.nan_to_num(t2)[..., None] * d2
    return p, ok & ok1 & ok2 & ok3 & ok4


#: the pupil solve's methods (`solve_exit_points(solver=...)`)
SOLVERS = ("secant", "newton")


def solve_exit_points(
    optics: CorneaOptics, camera: np.ndarray, target: np.ndarray, *, centre: np.ndarray | None = None,
    solver: str = "secant",
) -> ExitPoints:
    """Exit points on the anterior cornea of the rays from pupil points `target` (..., 3) to `camera`.

    Each point starts from the paraxial guess (`_first_guess`). `solver="secant"` (the default) runs Broyden's
    method (`secant2d`): one trace per iteration. With `centre` (..., 3), a point inside each outline of
    `target` (the outline's points along target's axis -2, where centre has size 1), the Jacobian of the centre's
    residual at its first guess starts the secant iteration of every point of its outline, saving the forward
    differences of the first step. `solver="newton"` is the forward-difference Newton (`newton2d`, three
    traces per iteration; the method before commit 9e352ca), kept as the reference the tests and the forward
    benchmark compare with. Both stop within 1e-11 mm of the solution."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown pupil solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    fused = _fused_residual(optics)
    q0 = _first_guess(optics, camera, target)
    if fused is None:  # mixed conic and biconic surfaces: the general trace

        def residual(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            p, ok = trace_into_eye(optics, q, source=camera)
            return p[..., :2] - target[..., :2], ok

        sol = newton2d(residual, q0, max_step=0.5)
    elif solver == "newton":
        sol = newton2d(fused(optics, camera, target, q0.shape[:-1]), q0, max_step=0.5, subset=True)
    else:
        jacobian = None if centre is None else _centre_jacobian(optics, camera, centre, fused)
        sol = secant2d(fused(optics, camera, target, q0.shape[:-1]), q0, jacobian=jacobian, max_step=0.5)
    a, _ = optics.anterior.point(sol.q)
    miss = length(sol.residual)
    valid = sol.ok & (miss <= PUPIL_TOLERANCE_MM)
    return ExitPoints(point=a, residual_mm=miss, valid=valid)


def _fused_residual(optics: CorneaOptics):
    """The component-wise residual builder for the optics' surfaces (None when they mix conic and biconic)."""
    if isinstance(optics.anterior, Conic) and isinstance(optics.posterior, Conic):
        return _conic_residual
    if isinstance(optics.anterior, Biconic) and isinstance(optics.posterior, Biconic):
        return _biconic_residual
    return None


def _centre_jacobian(optics: CorneaOptics, camera: np.ndarray, centre: np.ndarray, fused) -> np.ndarray:
    """dr/dq (..., 2, 2) of the centre's residual at its first guess (forward differences; NaN where a trace
    failed). Not at its solution: the Jacobian changes far more between the centre and the outline (millimetres)
    than between the guess and the solution (a tenth of one), and the solve would cost 6-7 traces more."""
    c0 = _first_guess(optics, camera, centre)
    f = fused(optics, camera, centre, c0.shape[:-1])
    r, ok = f(c0, None)
    return np.where(ok[..., None, None], difference_jacobian(f, c0, r, None, 1e-7), np.nan)


def _conic_residual(optics: CorneaOptics, camera: np.ndarray, target: np.ndarray, batch: tuple[int, ...]):
    """The residual of `solve_exit_points` for conic corneas, traced component-wise (`fused.trace_conic`, the
    same numbers as `trace_into_eye`) and evaluable on a subset of the batch (`newton2d(subset=True)`)."""
    eta1 = np.asarray(optics.n_air, dtype=float) / np.asarray(optics.n_cornea, dtype=float)
    eta2 = np.asarray(optics.n_cornea, dtype=float) / np.asarray(optics.n_aqueous, dtype=float)
    ant, post = optics.anterior, optics.posterior
    fields = (ant.apex, ant.radius, ant.conic, ant.aperture, post.apex, post.radius, post.conic, post.aperture,
              np.asarray(optics.pupil_plane.z0), eta1, eta2, camera[..., 0], camera[..., 1], camera[..., 2],
              target[..., 0], target[..., 1])

    def residual(q: np.ndarray, index: tuple[np.ndarray, ...] | None) -> tuple[np.ndarray, np.ndarray]:
        f = fields if index is None else tuple(np.broadcast_to(v, batch)[index] for v in fields)
        x, y, ok = trace_conic(Conic(*f[0:4]), Conic(*f[4:8]), Plane(f[8]), f[9], f[10], q[..., 0], q[..., 1],
                               f[11:14])
        return np.stack([x - f[14], y - f[15]], axis=-1), ok

    return residual


def _biconic_residual(optics: CorneaOptics, camera: np.ndarray, target: np.ndarray, batch: tuple[int, ...]):
    """The residual of `solve_exit_points` for biconic corneas, traced component-wise (`fused.trace_biconic`,
    equal to `trace_into_eye` to rounding), evaluable on a subset of the batch (`newton2d(subset=True)`).

    The posterior intersection has no closed form; each element's Newton starts from the t its last trace
    found (the Jacobian's neighbouring rays, 1e-7 mm away, or the previous iterate): two steps instead of
    four from the guide quadric."""
    eta1 = np.asarray(optics.n_air, dtype=float) / np.asarray(optics.n_cornea, dtype=float)
    eta2 = np.asarray(optics.n_cornea, dtype=float) / np.asarray(optics.n_aqueous, dtype=float)
    pair = BiconicPair.of(optics.anterior, optics.posterior, optics.pupil_plane, batch)
    source = optics.anterior.in_surface_frame(camera)
    fields = tuple(np.broadcast_to(v, batch) for v in (eta1, eta2, source[..., 0], source[..., 1], source[..., 2],
                                                       target[..., 0], target[..., 1]))

    last_t: np.ndarray | None = None  # the posterior t of each element's latest trace (NaN: none)

    def residual(q: np.ndarray, index: tuple[np.ndarray, ...] | None) -> tuple[np.ndarray, np.ndarray]:
        nonlocal last_t
        f, sub = (fields, pair) if index is None else (tuple(v[index] for v in fields), pair.take(index))
        start = None if last_t is None else (last_t if index is None else last_t[index])
        x, y, ok, t = trace_biconic(sub, f[0], f[1], q[..., 0], q[..., 1], f[2:5], start)
        if index is None:
            last_t = t
        else:
            last_t[index] = t
        return np.stack([x - f[5], y - f[6]], axis=-1), ok

    return residual


def _first_guess(optics: CorneaOptics, camera: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Aim at the paraxial image of the target (about 1.13x larger, 15% shallower); on a biconic, where the ray
    meets its guide quadric (a guess needs no exact hit)."""
    image = target * np.array([1.13, 1.13, 0.85])
    direction = unit(image - camera)
    surface = optics.anterior
    t, ok = (surface.guide_intersect if isinstance(surface, Biconic) else surface.intersect)(camera, direction)
    hit = camera + np.nan_to_num(t)[..., None] * direction
    return np.where(ok[..., None], surface.coords(hit), surface.coords(image))


def pupil_boundary(
    centre_xy: np.ndarray,
    radius: np.ndarray,
    depth: np.ndarray,
    n_points: int = 30,
    *,
    eccentricity: np.ndarray | None = None,
    axis_deg: np.ndarray | None = None,
) -> np.ndarray:
    """`n_points` evenly spaced points (..., N, 3) on a circle of `radius` about centre_xy (..., 2) at z = depth.

    With `eccentricity` e (...) the stop is an ellipse of the same area (gkaModelEye's convention): semi-axes
    a = r (1 - e^2)^(-1/4) along `axis_deg` (from +x toward +y, eye-local frame) and b = r (1 - e^2)^(1/4);
    the points are at the ellipse's parametric angles 2 pi k / N."""
    if n_points < 5:
        raise ValueError("the pupil boundary needs at least 5 points for an ellipse fit")
    theta = 2.0 * np.pi * np.arange(n_points) / n_points
    r = np.asarray(radius)[..., None]
    if eccentricity is None:
        x = centre_xy[..., 0:1] + r * np.cos(theta)
        y = centre_xy[..., 1:2] + r * np.sin(theta)
    else:
        squeeze = (1.0 - np.asarray(eccentricity, dtype=float) ** 2)[..., None] ** 0.25
        phi = np.radians(np.zeros_like(squeeze) if axis_deg is None else np.asarray(axis_deg)[..., None])
        major, minor = r / squeeze * np.cos(theta), r * squeeze * np.sin(theta)
        x = centre_xy[..., 0:1] + major * np.cos(phi) - minor * np.sin(phi)
        y = centre_xy[..., 1:2] + major * np.sin(phi) + minor * np.cos(phi)
    z = np.broadcast_to(np.asarray(depth)[..., None], x.shape)
    return np.stack([x, y, z], axis=-1)
