"""Biconic (toric) corneas: known answers against the conic of revolution, a tri-axial ellipsoid, a brute-force
Fermat search for the glint and an independent per-ray scipy solve for the apparent pupil (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq, root

from eyehil.emulator.optics.biconic import Biconic, rotation_matrix
from eyehil.emulator.optics.conic import Conic, Plane
from eyehil.emulator.optics.glint import solve_glints
from eyehil.emulator.optics.pupil import CorneaOptics, pupil_boundary, solve_exit_points

RNG = np.random.default_rng(13)


def _biconic(rx, ry, qx, qy, axis=0.0, tilt=(0.0, 0.0), apex=(0.0, 0.0, 0.0), aperture=5.9) -> Biconic:
    return Biconic(np.array(apex, float), rotation_matrix(axis, tilt[0], tilt[1]), rx, ry, qx, qy, aperture)


@pytest.mark.parametrize(("radius", "q"), [(7.8, -0.2), (6.5, 0.0), (7.2, -0.6), (8.1, 0.3)])
def test_equal_radii_equal_the_conic_of_revolution(radius: float, q: float) -> None:
    conic = Conic(0.0, radius, q, 5.9)
    toric = _biconic(radius, radius, q, q, axis=37.0)  # the meridian angle is irrelevant when the radii agree
    xy = RNG.uniform(-4.0, 4.0, (500, 2))
    pc, okc = conic.point(xy)
    pb, okb = toric.point(xy @ rotation_matrix(37.0, 0, 0)[:2, :2])  # same eye-local (x, y)
    assert np.array_equal(okc, okb)
    np.testing.assert_allclose(pb[okb], pc[okc], atol=1e-12, rtol=0)
    np.testing.assert_allclose(toric.normal(pc[okc]), conic.normal(pc[okc]), atol=1e-12, rtol=0)
    p = np.column_stack([RNG.uniform(-3, 3, (500, 2)), np.full(500, 20.0)])
    u = -np.column_stack([RNG.uniform(-0.2, 0.2, (500, 2)), np.ones(500)])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for far in (False, True):
        tc, vc = conic.intersect(p, u, far=far)
        tb, vb = toric.intersect(p, u, far=far)
        assert np.array_equal(vc, vb) and vc.sum() > 300  # most rays meet the cap
        np.testing.assert_allclose(tb[vb], tc[vc], atol=1e-12, rtol=0)


def test_triaxial_ellipsoid_is_the_biconic_with_equal_k_over_r() -> None:
    a, bh, bv = 14.26, 10.43, 10.27  # gkaModelEye's default anterior cornea (Navarro 2006), axial, horiz., vert.
    toric = _biconic(bh**2 / a, bv**2 / a, bh**2 / a**2 - 1, bv**2 / a**2 - 1)
    p, ok = toric.point(RNG.uniform(-4, 4, (400, 2)))
    assert ok.all()
    on = (p[:, 0] / bh) ** 2 + (p[:, 1] / bv) ** 2 + ((p[:, 2] + a) / a) ** 2
    np.testing.assert_allclose(on, 1.0, atol=1e-12)
    grad = np.column_stack([p[:, 0] / bh**2, p[:, 1] / bv**2, (p[:, 2] + a) / a**2])
    np.testing.assert_allclose(toric.normal(p), grad / np.linalg.norm(grad, axis=1, keepdims=True), atol=1e-12)


def test_tilted_toric_intersection_lies_on_the_surface_and_the_normal_is_the_gradient() -> None:
    toric = _biconic(7.9, 7.5, -0.25, -0.1, axis=20.0, tilt=(3.0, -2.0), apex=(0.4, -0.2, -0.01))
    p = np.column_stack([RNG.uniform(-2, 2, (300, 2)), np.full(300, 30.0)])  # every ray within 4 mm of the axis
    u = -np.column_stack([RNG.uniform(-0.05, 0.05, (300, 2)), np.ones(300)])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    t, ok = toric.intersect(p, u)
    assert ok.all()
    hit = p + t[:, None] * u
    assert toric.on_cap(hit, tol=1e-10).all()
    # the normal is orthogonal to the surface: finite differences along two surface directions
    q = toric.coords(hit)
    hx, hy = np.array([1e-6, 0.0]), np.array([0.0, 1e-6])
    du = (toric.point(q + hx)[0] - toric.point(q - hx)[0]) / 2e-6
    dv = (toric.point(q + hy)[0] - toric.point(q - hy)[0]) / 2e-6
    n = toric.normal(hit)
    assert np.max(np.abs(np.einsum("ij,ij->i", n, du))) < 1e-7
    assert np.max(np.abs(np.einsum("ij,ij->i", n, dv))) < 1e-7
    assert np.all(n @ toric.rotation[:, 2] > 0)  # outward


def _sag(x, y, rx, ry, qx, qy):
    """The biconic sag, written out again for the independent checks (surface frame)."""
    cx, cy = 1 / rx, 1 / ry
    return (cx * x * x + cy * y * y) / (1 + np.sqrt(1 - (1 + qx) * (cx * x) ** 2 - (1 + qy) * (cy * y) ** 2))


def _surface_point(u, v, rx, ry, qx, qy, axis_deg):
    """Eye-local point of an untilted biconic at apex 0 from surface coordinates (u, v)."""
    c, s = np.cos(np.radians(axis_deg)), np.sin(np.radians(axis_deg))
    return np.stack([c * u - s * v, s * u + c * v, -_sag(u, v, rx, ry, qx, qy)], axis=-1)


def _path_minimum(led, cam, shape, centre_uv, half_width):
    """Brute force: the surface point of least optical path led -> G -> cam (Fermat; a convex mirror's
    reflection path is the shortest), by zooming a dense grid. Lengths are compared as differences from the
    grid centre, written without cancellation: |A - G| - |A - G0| = (G - G0).(G + G0 - 2A) / (|A-G| + |A-G0|)."""
    uv = np.array(centre_uv, float)
    for _ in range(12):
        g1 = np.linspace(-half_width, half_width, 61)
        uu, vv = np.meshgrid(uv[0] + g1, uv[1] + g1, indexing="ij")
        g = _surface_point(uu, vv, *shape)
        g0 = _surface_point(np.array(uv[0]), np.array(uv[1]), *shape)
        diff = 0.0
        for a in (led, cam):
            num = np.einsum("...k,...k->...", g - g0, g + g0 - 2 * a)
            diff = diff + num / (np.linalg.norm(a - g, axis=-1) + np.linalg.norm(a - g0))
        i, j = np.unravel_index(np.argmin(diff), diff.shape)
        uv = np.array([uu[i, j], vv[i, j]])
        half_width /= 6.0
    return _surface_point(uv[0], uv[1], *shape)


@pytest.mark.parametrize("case", range(4))
def test_glint_of_a_toric_cornea_matches_a_brute_force_fermat_search(case: int) -> None:
    rng = np.random.default_rng(100 + case)
    shape = (7.9, 7.4 + 0.1 * case, -0.3, -0.1, 15.0 + 40 * case)  # R_x, R_y, Q_x, Q_y, axis
    led = np.array([rng.uniform(-150, 150), rng.uniform(-60, 60), 600.0])
    cam = np.array([rng.uniform(-40, 40), rng.uniform(-160, -60), 620.0])
    toric = _biconic(*shape[:4], axis=shape[4])
    g = solve_glints(toric, led, cam)
    assert g.valid and g.residual_mm <= 1e-4
    c, s = np.cos(np.radians(shape[4])), np.sin(np.radians(shape[4]))
    start = np.array([[c, s], [-s, c]]) @ g.point[:2]  # only to centre the search; its width covers 0.5 mm
    brute = _path_minimum(led, cam, shape, start + rng.uniform(-0.2, 0.2, 2), 0.5)
    assert np.linalg.norm(g.point - brute) < 1e-6


def _refract(d, n, n1, n2):
    """Snell's law written out again (n facing against d)."""
    n = n if np.dot(n, d) < 0 else -n
    cos_i = -np.dot(n, d)
    eta = n1 / n2
    k = 1 - eta**2 * (1 - cos_i**2)
    return eta * d + (eta * cos_i - np.sqrt(k)) * n


def _normal(p, shape, axis):
    """Normal from the implicit quartic of the biconic, G = S^2 - 2 S w + w^2 A (w = -z, S = c_x u^2 + c_y v^2,
    A = k_x c_x^2 u^2 + k_y c_y^2 v^2): a different formula from the module's sag gradient."""
    rx, ry, qx, qy = shape
    cx, cy, kx, ky = 1 / rx, 1 / ry, 1 + qx, 1 + qy
    c, s = np.cos(np.radians(axis)), np.sin(np.radians(axis))
    u, v, w = c * p[0] + s * p[1], -s * p[0] + c * p[1], -p[2]
    big_s, big_a = cx * u * u + cy * v * v, kx * cx * cx * u * u + ky * cy * cy * v * v
    gu = 2 * big_s * 2 * cx * u - 2 * 2 * cx * u * w + w * w * 2 * kx * cx * cx * u
    gv = 2 * big_s * 2 * cy * v - 2 * 2 * cy * v * w + w * w * 2 * ky * cy * cy * v
    gz = -(-2 * big_s + 2 * w * big_a)
    n = np.array([c * gu - s * gv, s * gu + c * gv, gz])
    return n / np.linalg.norm(n)


def _forward_trace(p, d, surfaces, indices):
    """Trace a ray from the pupil point p along d out through posterior then anterior cornea (brentq hits)."""
    for (apex, shape, axis), (n1, n2) in zip(surfaces, indices, strict=True):
        c, s = np.cos(np.radians(axis)), np.sin(np.radians(axis))

        def f(t, p=p, d=d, apex=apex, shape=shape, c=c, s=s):
            x = p + t * d
            u, v = c * x[0] + s * x[1], -s * x[0] + c * x[1]
            return x[2] - apex + _sag(u, v, *shape)

        t = brentq(f, 0.0, 5.0, xtol=1e-15, rtol=1e-15)
        p = p + t * d
        n = _normal(p - [0, 0, apex], shape, axis)
        d = _refract(d, n, n1, n2)
    return p, d


def test_apparent_pupil_through_a_toric_cornea_matches_a_per_ray_scipy_solve() -> None:
    front, back = (7.85, 7.55, -0.25, -0.15), (6.6, 6.3, -0.3, -0.2)
    axis_f, axis_b, cct, depth = 12.0, 95.0, 0.55, 3.6
    n_air, n_cornea, n_aqueous = 1.0, 1.376, 1.3374
    optics = CorneaOptics(_biconic(*front, axis=axis_f), _biconic(*back, axis=axis_b, apex=(0, 0, -cct)),
                          Plane(-depth), np.asarray(n_air), np.asarray(n_cornea), np.asarray(n_aqueous))
    camera = np.array([60.0, -120.0, 600.0])
    target = pupil_boundary(np.array([0.2, 0.3]), np.asarray(2.4), np.asarray(-depth), 12,
                            eccentricity=np.asarray(0.3), axis_deg=np.asarray(70.0))
    exits = solve_exit_points(optics, camera, target)
    assert exits.valid.all()
    focal = 4666.67
    towards = -camera / np.linalg.norm(camera)
    e1 = np.cross([0.0, 1.0, 0.0], towards)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(towards, e1)

    def pixel(a):
        v = a - camera
        return focal * np.array([v @ e1, v @ e2]) / (v @ towards)

    surfaces = [(-cct, back, axis_b), (0.0, front, axis_f)]
    indices = [(n_aqueous, n_cornea), (n_cornea, n_air)]
    for p, a in zip(target, exits.point, strict=True):
        def miss(angles, p=p):
            d = np.array([np.sin(angles[0]) * np.cos(angles[1]), np.sin(angles[0]) * np.sin(angles[1]),
                          np.cos(angles[0])])
            q, d_out = _forward_trace(p, d, surfaces, indices)
            w = camera - q
            off = w - (w @ d_out) * d_out
            return [off @ e1, off @ e2]

        guess = a - p
        guess /= np.linalg.norm(guess)
        start = [np.arccos(guess[2]), np.arctan2(guess[1], guess[0])]
        sol = root(miss, start, tol=1e-13, method="hybr")  # may stop on "no progress" at rounding level
        assert np.max(np.abs(miss(sol.x))) < 1e-8  # mm: the ray passes the camera's nodal point
        d = np.array([np.sin(sol.x[0]) * np.cos(sol.x[1]), np.sin(sol.x[0]) * np.sin(sol.x[1]), np.cos(sol.x[0])])
        exit_point, _ = _forward_trace(p, d, surfaces, indices)
        assert np.max(np.abs(pixel(exit_point) - pixel(a))) < 1e-4  # px


def _tilted_optics() -> CorneaOptics:
    """Tilted and decentred toric surfaces with different meridians: every frame change of the trace used."""
    front = _biconic(7.85, 7.5, -0.25, -0.1, axis=15.0, tilt=(2.5, -1.5), apex=(0.3, -0.2, 0.0))
    back = _biconic(6.6, 6.25, -0.3, -0.2, axis=100.0, tilt=(-1.0, 2.0), apex=(0.25, -0.15, -0.55))
    return CorneaOptics(front, back, Plane(-3.6), np.asarray(1.0), np.asarray(1.376), np.asarray(1.3374))


def test_component_wise_biconic_trace_equals_the_general_trace() -> None:
    """`fused.trace_biconic` (the toric pupil solve's hot loop, each surface in its own frame) gives the numbers of
    `trace_into_eye` to rounding and the same validity, over and beyond the cornea, cold and warm started."""
    from eyehil.emulator.optics.fused import BiconicPair, trace_biconic
    from eyehil.emulator.optics.pupil import trace_into_eye

    optics = _tilted_optics()
    q = RNG.uniform(-7.0, 7.0, (40, 60, 2))
    cam = np.stack([RNG.uniform(-300, 300, (40, 1)), RNG.uniform(-300, 300, (40, 1)),
                    RNG.uniform(5, 900, (40, 1))], axis=-1)
    p, ok = trace_into_eye(optics, q, source=cam)
    pair = BiconicPair.of(optics.anterior, optics.posterior, optics.pupil_plane, q.shape[:-1])
    source = optics.anterior.in_surface_frame(cam)
    eta1, eta2 = np.asarray(1.0 / 1.376), np.asarray(1.376 / 1.3374)
    with np.errstate(invalid="ignore"):
        x, y, ok2, t = trace_biconic(pair, eta1, eta2, q[..., 0], q[..., 1], tuple(np.moveaxis(source, -1, 0)))
        near = q + RNG.uniform(-1e-3, 1e-3, q.shape)  # a neighbouring ray, started from this one's t
        xw, yw, okw, _ = trace_biconic(pair, eta1, eta2, near[..., 0], near[..., 1],
                                       tuple(np.moveaxis(source, -1, 0)), t)
        xc, yc, okc, _ = trace_biconic(pair, eta1, eta2, near[..., 0], near[..., 1],
                                       tuple(np.moveaxis(source, -1, 0)))
    assert 0.2 < ok.mean() < 0.95  # both outcomes exercised
    np.testing.assert_array_equal(ok2, ok)
    np.testing.assert_allclose(np.stack([x, y], axis=-1)[ok], p[ok][:, :2], atol=1e-11, rtol=0)
    assert np.isfinite(t[ok2]).all() and np.isnan(t).any()  # NaN where the posterior is missed
    np.testing.assert_array_equal(okw, okc)
    np.testing.assert_allclose(np.stack([xw, yw], axis=-1)[okc], np.stack([xc, yc], axis=-1)[okc], atol=1e-11,
                               rtol=0)


def test_warm_started_toric_pupil_solve_equals_the_general_newton() -> None:
    """`solve_exit_points` on biconics (component-wise, warm-started posterior, subset Newton) finds the exit
    points of the general-path Newton (`trace_into_eye` residuals) to 1e-9 mm."""
    from eyehil.emulator.optics.newton import newton2d
    from eyehil.emulator.optics.pupil import _first_guess, trace_into_eye

    optics = _tilted_optics()
    camera = np.stack([RNG.uniform(-200, 200, (25, 1)), RNG.uniform(-150, 150, (25, 1)),
                       RNG.uniform(400, 800, (25, 1))], axis=-1)
    target = pupil_boundary(np.array([0.3, -0.2]), np.asarray(2.2), np.asarray(-3.6), 24)
    exits = solve_exit_points(optics, camera, target)

    def residual(q):
        p, ok = trace_into_eye(optics, q, source=camera)
        return p[..., :2] - target[..., :2], ok

    general = newton2d(residual, _first_guess(optics, camera, target), max_step=0.5)
    a, _ = optics.anterior.point(general.q)
    assert exits.valid.mean() > 0.9
    np.testing.assert_array_equal(exits.valid, general.ok & (np.linalg.norm(general.residual, axis=-1) <= 1e-6))
    np.testing.assert_allclose(exits.point[exits.valid], a[exits.valid], atol=1e-9, rtol=0)
