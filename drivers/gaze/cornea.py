"""Corneal centre and pupil centre from image features, for a spherical cornea (world frame, mm).

Guestrin & Eizenman 2006 (IEEE TBME 53(6):1124-1133), equations numbered as in Guestrin's PhD
thesis (Univ. Toronto, 2010). Symbols: o camera nodal point; l_i LED i; e_i unit direction from o
through glint i (into the scene, = (o - u_i)/|o - u_i|); c centre of corneal curvature; R corneal
radius; p pupil centre, K = |p - c|; n1 index of cornea+aqueous, n2 = 1 of air.

Two or more LEDs (thesis 3.8): each plane {o, l_i, u_i} contains c, so c = o + k_c b^ with b^ the
unit direction common to all planes (the cross product of the two plane normals; for more LEDs,
the least-squares null vector of the stacked normals), signed to point into the scene. The scalar
k_c solves the reflection law for every glint: q_i = o + k_qi e_i, the near intersection of the
glint ray with the sphere |x - c| = R,
    k_qi = k_c (e_i.b^) - sqrt(k_c^2 (e_i.b^)^2 - k_c^2 + R^2),
    f_i(k_c) = (l^_i - o^_i).(q_i - c) = 0,   l^_i = unit(l_i - q_i), o^_i = unit(o - q_i),
in least squares over i: a bracketed root of sum_i f_i (monotone in k_c between k_c = R and the
grazing limit R / max_i |e_i x b^|; a few bisections, then Newton steps kept inside the bracket),
then Gauss-Newton steps on sum_i f_i^2 (`distance="all-glints"`, eyehil's choice). With
`distance=i` (an LED index), k_c is instead the root of f_i alone: the reflection law of glint i
holds exactly and the other glints only set the direction b^ (what the published study's code did
with its first LED). On a spherical cornea every glint's root is the same k_c, so both agree; on an
aspheric cornea each glint sees a different local curvature and the one-glint distance carries that
glint's bias in full, where least squares averages the glints' biases.

One LED: c lies on a one-parameter curve c(k_q) = q - R n^, q = o + k_q e, n^ = unit(l^ + o^) (the
surface normal bisects the directions to LED and camera). A known distance D = |c - o| from the
camera nodal point to the corneal centre (chin rest, or measured at calibration) supplies the
missing scalar: |c(k_q) - o| = D, bisected over k_q in [D - 2R, D].

Pupil centre (thesis 3.29-3.37): refraction of the pupil ray at the sphere,
    r = o + k_r e_v (near intersection), zeta = -e_v, eta = (r - c)/R,
    iota = (n2/n1) [(eta.zeta - sqrt((n1/n2)^2 - 1 + (eta.zeta)^2)) eta - zeta],
    k_p = -(r - c).iota - sqrt(((r - c).iota)^2 - (R^2 - K^2)),  p = r + k_p iota.
All functions are batched over leading dimensions; samples without a solution give NaN.
"""

from __future__ import annotations

import numpy as np

from eyehil.drivers.gaze.geometry import Camera

_BISECTIONS = 60
_BRACKET_BISECTIONS = 8
_NEWTON_STEPS = 5
_GAUSS_NEWTON_STEPS = 4


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _bisect(g, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Root of an increasing g in [lo, hi], elementwise; NaN where g(lo) < 0 < g(hi) fails."""
    bracketed = (g(lo) < 0) & (g(hi) > 0)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        below = g(mid) < 0
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return np.where(bracketed, 0.5 * (lo + hi), np.nan)


def _bracketed_root(g, lo: np.ndarray, hi: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
    """Root of an increasing g in [lo, hi], elementwise, to about machine precision; NaN if not bracketed.

    A few bisections narrow the bracket (skipped when `start`, a nearby root, is given), then Newton
    steps (forward-difference slope) that stay inside the current bracket (a step leaving it is
    replaced by bisection).
    """
    bracketed = (g(lo) < 0) & (g(hi) > 0)
    if start is None:
        for _ in range(_BRACKET_BISECTIONS):
            mid = 0.5 * (lo + hi)
            below = g(mid) < 0
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        x = 0.5 * (lo + hi)
    else:
        x = np.where(np.isfinite(start) & (start > lo) & (start < hi), start, 0.5 * (lo + hi))
    for _ in range(_NEWTON_STEPS):
        h = 1e-7 * np.abs(x)
        gx = g(x)
        slope = (g(x + h) - gx) / h
        below = gx < 0
        lo, hi = np.where(below, x, lo), np.where(below, hi, x)
        with np.errstate(divide="ignore", invalid="ignore"):
            new = x - gx / slope
        inside = np.isfinite(new) & (new >= lo) & (new <= hi)
        x = np.where(inside, new, 0.5 * (lo + hi))
    return np.where(bracketed, x, np.nan)


def common_direction(o: np.ndarray, leds: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Unit direction b^ (..., 3) shared by the planes {o, l_i, o + e_i}, pointing into the scene.

    leds (n, 3), e (..., n, 3) with n >= 2: the right singular vector of the stacked plane normals
    (l_i - o) x e_i with the smallest singular value (the exact cross product for n = 2).
    """
    normals = _unit(np.cross(leds - o, e))
    b = np.linalg.svd(normals)[2][..., -1, :]
    return b * np.sign(_dot(b, e.mean(axis=-2)))[..., None]


def reflection_residuals(
    k_c: np.ndarray, o: np.ndarray, leds: np.ndarray, e: np.ndarray, b: np.ndarray, R
) -> np.ndarray:
    """f_i(k_c) (..., n) mm of thesis 3.8 for c = o + k_c b^ (beyond grazing, q is the tangent point)."""
    k = np.asarray(k_c)[..., None]
    eb = _dot(e, b[..., None, :])
    R = np.asarray(R)[..., None]
    k_q = k * eb - np.sqrt(np.clip(k**2 * eb**2 - k**2 + R**2, 0.0, None))
    q = o + k_q[..., None] * e
    c = o + k[..., None] * b[..., None, :]
    return _dot(_unit(leds - q) + e, q - c)


def glint_rays(camera: Camera, leds: np.ndarray, glints_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit glint rays e (..., n_leds, 3) and the common direction b^ (..., 3): what c depends on besides R."""
    e = camera.ray_directions(glints_px)
    return e, common_direction(camera.o, leds, e)


def corneal_distance(o: np.ndarray, leds: np.ndarray, e: np.ndarray, b: np.ndarray, R,
                     distance: str | int = "all-glints", start: np.ndarray | None = None) -> np.ndarray:
    """k_c (...) mm with c = o + k_c b^, from glint rays e (..., n, 3) and b^ (..., 3) (`glint_rays`).

    `distance`: "all-glints" or an LED index (module docstring); `start` (...) a nearby k_c (e.g. at a
    slightly different R) to start Newton from. NaN where no root is bracketed.
    """
    R = np.broadcast_to(np.asarray(R, float), b.shape[:-1])
    eb = _dot(e, b[..., None, :])  # (..., n)
    grazing = R / np.sqrt(np.clip(1.0 - eb**2, 1e-300, None)).max(axis=-1)
    lo, hi = R * (1.0 + 1e-9), grazing * (1.0 - 1e-9)
    f = _reflection_law(o, leds, e, b, eb, R)
    if distance != "all-glints":
        i = int(distance)
        if not 0 <= i < len(leds):
            raise ValueError(f"distance glint {i} out of range for {len(leds)} LEDs")
        return _bracketed_root(lambda k: f(k)[..., i], lo, hi, start)
    k_c = _bracketed_root(lambda k: np.sum(f(k), axis=-1), lo, hi, start)
    for _ in range(_GAUSS_NEWTON_STEPS):
        # central slope with a wide step: the f_i are nearly linear in k_c, and at the least-squares point
        # f . df cancels between glints, so a narrow step's rounding noise would jitter k_c by ~1e-5 mm
        h = 1e-4 * k_c
        fk = f(k_c)
        df = (f(k_c + h) - f(k_c - h)) / (2 * h[..., None])
        step = _dot(fk, df) / _dot(df, df)
        k_c = k_c - np.where(np.isfinite(step), step, 0.0)
    return k_c


def _reflection_law(o: np.ndarray, leds: np.ndarray, e: np.ndarray, b: np.ndarray, eb: np.ndarray, R):
    """`reflection_residuals` as a function of k_c alone, in scalar products precomputed once.

    With L_i = l_i - o, q - c = k_q e - k_c b^ and l_i - q = L_i - k_q e, so
    f_i = [k_q (L.e) - k_c (L.b) - k_q^2 + k_q k_c (e.b)] / |L - k_q e| + k_q - k_c (e.b).
    """
    L = np.asarray(leds, float) - o
    Le, Lb, LL, R2 = _dot(L, e), L @ np.moveaxis(b, -1, 0).reshape(3, -1), _dot(L, L), np.asarray(R)[..., None] ** 2
    Lb = np.moveaxis(Lb.reshape(len(L), *b.shape[:-1]), 0, -1)

    def f(k_c: np.ndarray) -> np.ndarray:
        k = np.asarray(k_c)[..., None]
        kb = k * eb
        k_q = kb - np.sqrt(np.clip(kb**2 - k**2 + R2, 0.0, None))
        dist = np.sqrt(LL - 2 * k_q * Le + k_q**2)
        return (k_q * Le - k * Lb - k_q**2 + k_q * kb) / dist + k_q - kb

    return f


def corneal_centre(camera: Camera, leds: np.ndarray, glints_px: np.ndarray, R, distance: str | int = "all-glints"
                   ) -> np.ndarray:
    """Centre of corneal curvature c (..., 3) world mm from glints (..., n_leds >= 2, 2) px.

    R (mm) is a scalar or broadcasts against the batch shape. `distance`: "all-glints" (k_c by least
    squares over every glint's reflection law) or an LED index i (the root of glint i's law alone);
    see the module docstring. NaN where no solution is bracketed.
    """
    e, b = glint_rays(camera, leds, glints_px)
    return camera.o + corneal_distance(camera.o, leds, e, b, R, distance)[..., None] * b


def corneal_centre_one_led(camera: Camera, led: np.ndarray, glint_px: np.ndarray, R, distance_mm) -> np.ndarray:
    """Centre of corneal curvature c (..., 3) world mm from one glint (..., 2) px and |c - o| = distance_mm.

    R and distance_mm (mm) are scalars or broadcast against the batch shape.
    """
    o = camera.o
    e = camera.ray_directions(glint_px)
    R = np.broadcast_to(np.asarray(R, float), e.shape[:-1])
    D = np.broadcast_to(np.asarray(distance_mm, float), e.shape[:-1])

    def centre(k_q):
        q = o + k_q[..., None] * e
        return q - R[..., None] * _unit(_unit(np.asarray(led, float) - q) - e)

    k_q = _bisect(lambda k: np.linalg.norm(centre(k) - o, axis=-1) - D, D - 2 * R, D.copy())
    return centre(k_q)


def pupil_centre(camera: Camera, pupil_px: np.ndarray, c: np.ndarray, R, K, n1: float, n2: float = 1.0) -> np.ndarray:
    """Pupil centre p (..., 3) world mm by refraction of the pupil-centre ray at the corneal sphere.

    pupil_px (..., 2); c (..., 3) world mm; R, K (mm) scalars or batch-broadcastable. NaN where the
    ray misses the cornea or no point at distance K from c lies on the refracted ray.
    """
    return refracted_pupil_centre(camera.o, camera.ray_directions(pupil_px), c, R, K, n1, n2)


def refracted_pupil_centre(o: np.ndarray, e: np.ndarray, c: np.ndarray, R, K, n1: float, n2: float = 1.0
                           ) -> np.ndarray:
    """`pupil_centre` from the unit pupil-centre ray e (..., 3) out of the nodal point o (world)."""
    R = np.asarray(R, float)
    K = np.asarray(K, float)
    oc = o - c
    along = _dot(e, oc)
    with np.errstate(invalid="ignore"):  # a negative discriminant is a miss: NaN, as documented
        k_r = -along - np.sqrt(along**2 - (_dot(oc, oc) - R**2))
        r = o + k_r[..., None] * e
        zeta = -e
        eta = (r - c) / R[..., None]
        ez = _dot(eta, zeta)[..., None]
        ratio = n1 / n2
        iota = (ez - np.sqrt(ratio**2 - 1.0 + ez**2)) * eta / ratio - zeta / ratio
        rc_iota = _dot(r - c, iota)
        k_p = -rc_iota - np.sqrt(rc_iota**2 - (R**2 - K**2))
    return r + k_p[..., None] * iota
