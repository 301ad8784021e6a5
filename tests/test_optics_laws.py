"""Known answers for the optical primitives: refraction, reflection, conic intersection, camera, ellipse fit."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.emulator.optics.camera import PinholeCamera
from eyehil.emulator.optics.conic import Conic
from eyehil.emulator.optics.ellipse import fit_ellipse
from eyehil.emulator.optics.rays import affine, reflect, refract, unit

RNG = np.random.default_rng(42)


def _random_rays(n: int) -> tuple[np.ndarray, np.ndarray]:
    normals = unit(RNG.normal(size=(n, 3)))
    d = unit(RNG.normal(size=(n, 3)))
    d = np.where((np.einsum("ij,ij->i", d, normals) > 0)[:, None], -d, d)  # incoming against the normal
    return d, normals


def test_refraction_obeys_snell_and_stays_in_the_plane_of_incidence() -> None:
    d, n = _random_rays(10_000)
    n1, n2 = 1.0, 1.376
    t, ok = refract(d, n, n1, n2)
    assert ok.all()
    sin_i = np.linalg.norm(np.cross(d, n), axis=1)
    sin_t = np.linalg.norm(np.cross(t, n), axis=1)
    np.testing.assert_allclose(n1 * sin_i, n2 * sin_t, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ij,ij->i", np.cross(d, n), t), 0.0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", t, n) < 0)  # transmitted, not reflected


def test_refraction_known_answer_and_total_internal_reflection() -> None:
    d = np.array([np.sin(np.radians(30)), 0.0, -np.cos(np.radians(30))])
    t, ok = refract(d, np.array([0.0, 0.0, 1.0]), 1.0, 1.5)
    assert ok and abs(t[0] - 1 / 3) < 1e-12
    glancing = np.array([np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))])
    _, ok = refract(glancing, np.array([0.0, 0.0, 1.0]), 1.5, 1.0)  # sin 60 * 1.5 > 1
    assert not ok


def test_reflection_law() -> None:
    d, n = _random_rays(10_000)
    r = reflect(d, n)
    np.testing.assert_allclose(np.einsum("ij,ij->i", r, n), -np.einsum("ij,ij->i", d, n), atol=1e-12)
    np.testing.assert_allclose(np.cross(r, n), np.cross(d, n), atol=1e-12)  # tangential part kept: same plane
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), 1.0, atol=1e-12)


def test_sphere_intersection_matches_closed_form() -> None:
    radius, apex = 7.8, 0.0
    centre = np.array([0.0, 0.0, apex - radius])
    sphere = Conic(apex, radius, 0.0, 1e9)
    origins = np.column_stack([RNG.uniform(-3, 3, 2000), RNG.uniform(-3, 3, 2000), RNG.uniform(20, 50, 2000)])
    dirs = unit(centre + RNG.uniform(-4, 4, (2000, 3)) - origins)
    t, ok = sphere.intersect(origins, dirs)
    oc = origins - centre
    b = np.einsum("ij,ij->i", oc, dirs)
    disc = b**2 - (np.einsum("ij,ij->i", oc, oc) - radius**2)
    expected = -b - np.sqrt(disc)
    assert ok.all()
    np.testing.assert_allclose(t, expected, atol=1e-10)


def test_ellipsoid_intersection_lies_on_the_surface_and_the_normal_is_the_gradient() -> None:
    s = Conic(-0.5, 6.5, -0.3, 6.0)
    origins = np.column_stack([RNG.uniform(-2, 2, 500), RNG.uniform(-2, 2, 500), np.full(500, 5.0)])
    dirs = unit(np.column_stack([RNG.uniform(-0.2, 0.2, 500), RNG.uniform(-0.2, 0.2, 500), -np.ones(500)]))
    t, ok = s.intersect(origins, dirs)
    p = origins + t[:, None] * dirs
    w = -0.5 - p[:, 2]
    np.testing.assert_allclose(p[:, 0] ** 2 + p[:, 1] ** 2 + 0.7 * w**2 - 13.0 * w, 0.0, atol=1e-10)
    n = s.normal(p)
    grad = np.column_stack([2 * p[:, 0], 2 * p[:, 1], -(2 * 0.7 * w - 13.0)])
    np.testing.assert_allclose(n, unit(grad), atol=1e-12)
    assert ok.all()


def test_ray_missing_the_cap_is_invalid_not_nan_silently() -> None:
    s = Conic(0.0, 7.8, -0.2, 5.9)
    t, ok = s.intersect(np.array([20.0, 0.0, 5.0]), np.array([0.0, 0.0, -1.0]))
    assert not ok and np.isnan(t)


def test_conic_rejects_zero_radius() -> None:
    with pytest.raises(ValueError, match="radius"):
        Conic(0.0, 0.0, 0.0, 5.0)


def test_camera_known_answer_and_orientation() -> None:
    cam = PinholeCamera.from_angles(position=np.array([0.0, 0.0, 600.0]), focal_px=(1000.0, 1000.0),
                                    principal_px=(320.0, 240.0), resolution_px=(640, 480))
    px, front = cam.project(np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]]))
    np.testing.assert_allclose(px, [[320, 240], [320 + 1000 * 10 / 600, 240], [320, 240 - 1000 * 10 / 600]])
    assert front.all()
    pitch = np.degrees(np.arctan2(150.5, 615))
    tilted = PinholeCamera.from_angles(position=np.array([0.0, -150.5, 615.0]), pitch_deg=pitch,
                                       focal_px=(4666.67, 4666.67), principal_px=(320.0, 240.0),
                                       resolution_px=(640, 480))
    px, _ = tilted.project(np.zeros(3))
    np.testing.assert_allclose(px, [320.0, 240.0], atol=1e-9)  # aimed at the origin


def test_camera_radial_distortion_moves_points_outward() -> None:
    kw = dict(position=np.array([0.0, 0.0, 600.0]), focal_px=(1000.0, 1000.0), principal_px=(320.0, 240.0),
              resolution_px=(640, 480))
    plain, barrel = PinholeCamera.from_angles(**kw), PinholeCamera.from_angles(**kw, distortion=(0.1, 0.0))
    p = np.array([60.0, 0.0, 0.0])
    x = 0.1
    np.testing.assert_allclose(barrel.project(p)[0][0] - 320, 1000 * x * (1 + 0.1 * x * x))
    assert barrel.project(p)[0][0] > plain.project(p)[0][0]


@pytest.mark.parametrize("angle", [0.0, 17.0, 90.0, 135.0])
def test_ellipse_fit_recovers_an_exact_ellipse(angle: float) -> None:
    th = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    a, b, t = 25.0, 14.0, np.radians(angle)
    pts = np.column_stack([300 + a * np.cos(th) * np.cos(t) - b * np.sin(th) * np.sin(t),
                           200 + a * np.cos(th) * np.sin(t) + b * np.sin(th) * np.cos(t)])
    weights = np.ones(30)
    weights[[3, 4, 5, 20]] = 0  # dropped points
    pts[[3, 4, 5, 20]] = np.nan
    e = fit_ellipse(pts[None], weights[None])
    assert e.valid[0]
    np.testing.assert_allclose(e.centre[0], [300, 200], atol=1e-9)
    np.testing.assert_allclose(e.axes[0], [2 * a, 2 * b], atol=1e-9)
    assert abs((e.angle_deg[0] - angle + 90) % 180 - 90) < 1e-7


def test_ellipse_fit_with_too_few_points_is_invalid() -> None:
    pts = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [2.0, 2.0]]])
    e = fit_ellipse(pts, np.array([[1, 1, 1, 1, 0]]))
    assert not e.valid[0]


def test_ellipse_fit_of_collinear_points_is_invalid_and_spares_the_rest_of_the_batch() -> None:
    th = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    pts = np.stack([np.column_stack([th, 2 * th + 1]), np.column_stack([10 + 3 * np.cos(th), 5 + 2 * np.sin(th)])])
    e = fit_ellipse(pts)
    assert not e.valid[0] and e.valid[1]
    np.testing.assert_allclose(e.axes[1], [6, 4], atol=1e-9)


def test_ellipse_fit_of_noisy_points_is_the_least_squares_eigenvector() -> None:
    """The element-wise eigenvector equals the general eigensolver's choice (Halir & Flusser: the eigenvector of
    M = C1^-1 (S1 + S2 T) with 4 a c - b^2 > 0), here computed with np.linalg.eig from the same scatter matrices."""
    rng = np.random.default_rng(5)
    th = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    pts = np.column_stack([40 + 9 * np.cos(th), 30 + 4 * np.sin(th)])[None] + rng.normal(0, 0.5, (50, 20, 2))
    e = fit_ellipse(pts)
    for k in range(50):
        x, y = (pts[k] - pts[k].mean(axis=0)).T
        d1, d2 = np.column_stack([x * x, x * y, y * y]), np.column_stack([x, y, np.ones_like(x)])
        t = -np.linalg.solve(d2.T @ d2, d2.T @ d1)
        m = np.array([[0, 0, 0.5], [0, -1, 0], [0.5, 0, 0]]) @ (d1.T @ d1 + d1.T @ d2 @ t)
        vecs = np.linalg.eig(m)[1].real
        a, b, c = vecs[:, np.argmax(4 * vecs[0] * vecs[2] - vecs[1] ** 2)]
        d, e_, _ = t @ [a, b, c]
        den = 4 * a * c - b * b
        centre = np.array([b * e_ - 2 * c * d, b * d - 2 * a * e_]) / den + pts[k].mean(axis=0)
        np.testing.assert_allclose(e.centre[k], centre, atol=1e-9)


def test_affine_is_the_matrix_product_plus_offset() -> None:
    rng = np.random.default_rng(2)
    m, o, p = rng.normal(size=(4, 3, 3, 3)), rng.normal(size=(4, 3, 3)), rng.normal(size=(4, 3, 7, 3))
    np.testing.assert_allclose(affine(m, o, p), np.einsum("abij,abnj->abni", m, p) + o[:, :, None], atol=1e-14)


def test_near_and_far_roots_of_a_chord_through_the_cap() -> None:
    """A ray along +x at depth w = 1 below the apex of a sphere (R 5) crosses the cap at x = -+3 (r^2 = 2Rw - w^2)."""
    cap = Conic(0.0, 5.0, 0.0, 5.0)
    origin, direction = np.array([-10.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])
    t_near, ok_near = cap.intersect(origin, direction)
    t_far, ok_far = cap.intersect(origin, direction, far=True)
    assert ok_near and ok_far
    assert t_near == pytest.approx(7.0, abs=1e-12) and t_far == pytest.approx(13.0, abs=1e-12)
    deeper = np.array([-10.0, 0.0, -6.0])  # below the equator (w > R): the back half is not optical surface
    _, ok = cap.intersect(deeper, direction)
    assert not ok
