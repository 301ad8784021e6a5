"""Known answers for the glint and apparent-pupil solvers and the line of sight."""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.surfaces import cornea_optics
from eyehil.emulator.fixation import line_of_sight
from eyehil.emulator.optics.conic import Conic
from eyehil.emulator.optics.glint import solve_glints
from eyehil.emulator.optics.pupil import pupil_boundary, solve_exit_points
from eyehil.emulator.optics.rays import unit

RNG = np.random.default_rng(7)


def test_glint_of_a_sphere_matches_the_symmetric_closed_form() -> None:
    """LED and camera at equal distance from the centre: the glint lies on the bisector, G = C + R unit(l + o)."""
    radius, n = 7.8, 500
    centre = np.array([0.0, 0.0, -radius])
    sphere = Conic(0.0, radius, 0.0, 7.0)
    axis = unit(np.column_stack([RNG.uniform(-0.3, 0.3, n), RNG.uniform(-0.3, 0.3, n), np.ones(n)]))
    side = unit(np.cross(axis, RNG.normal(size=(n, 3))))
    half = np.radians(RNG.uniform(2, 20, n))[:, None]
    dist = RNG.uniform(400, 800, n)[:, None]
    led = centre + dist * (np.cos(half) * axis + np.sin(half) * side)
    cam = centre + dist * (np.cos(half) * axis - np.sin(half) * side)
    g = solve_glints(sphere, led, cam)
    assert g.valid.all()
    np.testing.assert_allclose(g.point, centre + radius * axis, atol=1e-9)
    assert np.max(g.residual_mm) < 1e-9


def test_glint_of_an_ellipsoid_obeys_the_law_of_reflection() -> None:
    cornea = Conic(0.0, 7.6, -0.35, 5.9)
    led = np.column_stack([RNG.uniform(-200, 200, 300), RNG.uniform(-100, 100, 300), np.full(300, 650.0)])
    cam = np.array([0.0, -150.0, 615.0])
    g = solve_glints(cornea, led, cam)
    assert g.valid.all() and np.max(g.residual_mm) < 1e-4
    n = cornea.normal(g.point)
    bisector = unit(unit(led - g.point) + unit(cam - g.point))
    np.testing.assert_allclose(n, bisector, atol=1e-9)


def test_glint_off_the_cornea_is_invalid() -> None:
    cornea = Conic(0.0, 7.8, -0.2, 5.9)
    # LED and camera far to the side: the reflecting normal would point along +x, beyond the limbus
    g = solve_glints(cornea, np.array([600.0, 0.0, -5.0]), np.array([600.0, 40.0, -5.0]))
    assert not g.valid


def _single_surface_optics(stop_depth: float = 3.6):
    """One refracting surface (R 7.8, n 1.3375): the posterior cornea separates equal indices."""
    from eyehil.emulator.optics.conic import Plane
    from eyehil.emulator.optics.pupil import CorneaOptics

    n = 1.3375
    return CorneaOptics(Conic(0.0, 7.8, 0.0, 6.0), Conic(-0.5, 7.3, 0.0, 6.0), Plane(np.asarray(-stop_depth)),
                        np.asarray(1.0), np.asarray(n), np.asarray(n))


def test_entrance_pupil_of_a_single_surface_matches_paraxial_optics() -> None:
    """Paraxial: image of the stop at v with 1/v = (1 - n)/(-R) + n/(-d): v = -3.046 mm, m = n v / (-d) = 1.132."""
    n, radius, depth = 1.3375, 7.8, 3.6
    v = 1.0 / ((1.0 - n) / (-radius) + n / (-depth))
    m = n * v / (-depth)
    optics = _single_surface_optics(depth)
    point = np.array([0.1, 0.0, -depth])  # near the axis
    cams = np.array([[0.0, 0.0, 600.0], [8.0, 0.0, 600.0]])  # parallax between two viewpoints
    exits = solve_exit_points(optics, cams, np.broadcast_to(point, (2, 3)))
    assert exits.valid.all()
    d = unit(exits.point - cams)
    # closest approach of the two exit rays (extended back into the eye): the virtual image of the point
    w0 = cams[0] - cams[1]
    a, b, c = d[0] @ d[0], d[0] @ d[1], d[1] @ d[1]
    s = (b * (d[1] @ w0) - c * (d[0] @ w0)) / (a * c - b * b)
    image = cams[0] + s * d[0]
    assert abs(image[2] - v) / abs(v) < 0.01
    assert abs(image[0] / point[0] - m) / m < 0.01
    assert abs(m - 1.132) < 1e-3 and abs(v + 3.046) < 1e-3


def test_apparent_pupil_points_trace_back_to_the_pupil(eyes) -> None:
    media = Media.cauchy(850)
    optics = cornea_optics(eyes, media, 1)
    from eyehil.emulator.eye.surfaces import pupil_centre
    from eyehil.emulator.optics.pupil import trace_into_eye

    boundary = pupil_boundary(pupil_centre(eyes)[..., :2], eyes.pupil_radius, -eyes.stop_depth, 30)
    cam = np.array([5.0, -150.0, 600.0])
    exits = solve_exit_points(optics, cam, boundary)
    assert exits.valid.all() and exits.residual_mm.max() < 1e-6
    back, ok = trace_into_eye(optics, exits.point[..., :2], source=cam)
    assert ok.all()
    np.testing.assert_allclose(back, boundary, atol=1e-6)


def test_line_of_sight_makes_the_fovea_angle_and_crosses_the_stop_centre(eyes) -> None:
    los = line_of_sight(eyes, Media.cauchy(850))
    assert los.valid.all()
    h = np.degrees(np.arctan2(los.direction[:, 0], los.direction[:, 2]))
    v = np.degrees(np.arcsin(los.direction[:, 1]))
    np.testing.assert_allclose(h, eyes.alpha_h, atol=1e-9)
    np.testing.assert_allclose(v, eyes.alpha_v, atol=1e-9)
    left = line_of_sight(eyes.mirrored(), Media.cauchy(850))
    np.testing.assert_allclose(left.direction * [-1, 1, 1], los.direction, atol=1e-12)
    np.testing.assert_allclose(left.fovea * [-1, 1, 1], los.fovea, atol=1e-9)
    # the fovea lies temporal (x < 0 for a right eye), inferior, and within 0.3 mm of the depth of the
    # posterior pole (it sits 1-2 mm off the axis on a retina of radius ~11 mm: r^2 / 2R ~ 0.1-0.2 mm)
    assert np.all(los.fovea[:, 0] < 0) and np.all(los.fovea[:, 1] < 0)
    assert np.all(los.fovea[:, 2] > -eyes.axial_length) and np.all(los.fovea[:, 2] < -eyes.axial_length + 0.3)


def test_component_wise_pupil_trace_equals_the_general_trace_bit_for_bit(eyes) -> None:
    """`fused.trace_conic` (the pupil solve's hot loop) gives exactly the numbers of `trace_into_eye`, including
    rays that miss: exit points spread over and beyond the cornea, cameras near and far, off axis."""
    from eyehil.emulator.optics.fused import trace_conic
    from eyehil.emulator.optics.pupil import trace_into_eye

    optics = cornea_optics(eyes, Media.cauchy(850), 2)
    q = RNG.uniform(-7.0, 7.0, (len(eyes), 40, 50, 2))
    cam = np.stack([RNG.uniform(-300, 300, (40, 1)), RNG.uniform(-300, 300, (40, 1)),
                    RNG.uniform(5, 900, (40, 1))], axis=-1)
    p, ok = trace_into_eye(optics, q, source=cam)
    eta1 = np.asarray(optics.n_air) / np.asarray(optics.n_cornea)
    eta2 = np.asarray(optics.n_cornea) / np.asarray(optics.n_aqueous)
    with np.errstate(invalid="ignore"):
        x, y, ok2 = trace_conic(optics.anterior, optics.posterior, optics.pupil_plane, eta1, eta2, q[..., 0],
                                q[..., 1], (cam[..., 0], cam[..., 1], cam[..., 2]))
    assert 0.2 < ok.mean() < 0.95  # both outcomes exercised
    np.testing.assert_array_equal(ok2, ok)
    np.testing.assert_array_equal(np.stack([x, y], axis=-1)[ok], p[ok][:, :2])


def test_newton_on_a_subset_equals_the_full_batch_bit_for_bit(eyes) -> None:
    """newton2d(subset=True) evaluates only the moving elements late in the solve; the answer is unchanged."""
    from eyehil.emulator.eye.surfaces import pupil_centre
    from eyehil.emulator.optics import newton as newton_module
    from eyehil.emulator.optics.pupil import _conic_residual, _first_guess

    optics = cornea_optics(eyes, Media.cauchy(850), 2)
    boundary = pupil_boundary(pupil_centre(eyes)[..., :2], eyes.pupil_radius, -eyes.stop_depth, 30)[:, None]
    cam = np.array([[5.0, -150.0, 600.0], [-40.0, 60.0, 450.0]])[None, :, None]
    q0 = _first_guess(optics, cam, boundary)
    q0[0, 0, 0, :3] += 0.8  # three points start far off: they still move when the rest have converged
    f = _conic_residual(optics, cam, boundary, q0.shape[:-1])
    calls: list[int] = []

    def counted(q, index):
        calls.append(q[..., 0].size)
        return f(q, index)

    sub = newton_module.newton2d(counted, q0, max_step=0.5, subset=True)
    full = newton_module.newton2d(lambda q: f(q, None), q0, max_step=0.5)
    assert min(calls) < q0[..., 0].size / 2  # the subset path ran
    np.testing.assert_array_equal(sub.q, full.q)
    np.testing.assert_array_equal(sub.residual, full.residual)
    np.testing.assert_array_equal(sub.ok, full.ok)
    assert sub.iterations == full.iterations


def _oblique_pupil_problem(eyes):
    """The pupil solve of `eyes` seen by three cameras, one far off axis: (optics, cameras, boundary, centre)."""
    from eyehil.emulator.eye.surfaces import pupil_centre

    optics = cornea_optics(eyes, Media.cauchy(850), 2)
    boundary = pupil_boundary(pupil_centre(eyes)[..., :2], eyes.pupil_radius, -eyes.stop_depth, 30)[:, None]
    cams = np.array([[5.0, -150.0, 600.0], [-40.0, 60.0, 450.0], [330.0, -200.0, 420.0]])[None, :, None]
    return optics, cams, boundary, pupil_centre(eyes)[:, None, None]


def test_secant_pupil_solve_equals_the_newton_solve(eyes) -> None:
    """Broyden's method, started cold or from the pupil centre's Jacobian, finds Newton's exit points (to the
    solvers' own tolerance, 1e-11 mm in q) with the same validity."""
    optics, cams, boundary, centre = _oblique_pupil_problem(eyes)
    newton = solve_exit_points(optics, cams, boundary, solver="newton")
    for seeded in (None, centre):
        secant = solve_exit_points(optics, cams, boundary, centre=seeded)
        np.testing.assert_array_equal(secant.valid, newton.valid)
        assert newton.valid.mean() > 0.5
        np.testing.assert_allclose(secant.point[secant.valid], newton.point[newton.valid], atol=1e-9, rtol=0)
        assert secant.residual_mm[secant.valid].max() < 1e-9


def test_secant_pupil_solve_traces_fewer_rays(eyes, monkeypatch) -> None:
    """Counted: the seeded secant solve traces under 70 % of the rays of the forward-difference Newton (59 % on
    this problem; each of Newton's steps traces three rays, each of Broyden's one, but Broyden takes more)."""
    from eyehil.emulator.optics import pupil

    optics, cams, boundary, centre = _oblique_pupil_problem(eyes)
    traced: list[int] = []
    original = pupil.trace_conic

    def counted(*args):
        traced.append(np.size(args[6]))
        return original(*args)

    monkeypatch.setattr(pupil, "trace_conic", counted)
    solve_exit_points(optics, cams, boundary, solver="newton")
    newton = sum(traced)
    traced.clear()
    solve_exit_points(optics, cams, boundary, centre=centre)
    secant = sum(traced)
    assert secant < 0.7 * newton


def test_secant_on_a_subset_and_with_a_wrong_jacobian_still_converges() -> None:
    """A few elements start far off (the rest stop early: the subset path runs), and half start from a Jacobian
    of the wrong sign (their first step raises |r|: the forward-difference refresh recovers them)."""
    from eyehil.emulator.optics.newton import secant2d

    rng = np.random.default_rng(3)
    root = rng.uniform(-1, 1, (200, 2))

    def f(q, index):
        c = root if index is None else root[index]
        x, y = q[..., 0] - c[..., 0], q[..., 1] - c[..., 1]
        return np.stack([x + 0.3 * y**2 + 0.1 * x**3, y + 0.2 * x * y], axis=-1), np.ones(x.shape, bool)

    q0 = root + rng.normal(0, 0.05, root.shape)
    q0[:5] += 0.8
    jac = np.broadcast_to(np.eye(2), (200, 2, 2)).copy()
    jac[100:] *= -1.0
    sizes: list[int] = []
    sol = secant2d(lambda q, i: (sizes.append(q[..., 0].size), f(q, i))[1], q0, jacobian=jac, max_step=0.5)
    assert sol.ok.all()
    np.testing.assert_allclose(sol.q, root, atol=1e-10)
    assert np.abs(sol.residual).max() < 1e-10
    np.testing.assert_array_equal(sol.residual, f(sol.q, None)[0])  # the residual is f at the returned q
    assert min(sizes) < 100  # the subset path and the refresh ran


def test_unknown_pupil_solver_is_refused(eyes) -> None:
    import pytest

    optics, cams, boundary, _ = _oblique_pupil_problem(eyes)
    with pytest.raises(ValueError, match="unknown pupil solver"):
        solve_exit_points(optics, cams, boundary, solver="bisection")
