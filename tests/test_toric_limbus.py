"""The rendered limbus of a toric, tilted, displaced cornea against an independent computation (issue 13).

Independent of `render.geometry.limbus_points`: the corneal edge is found by solving the biconic's implicit
equation per meridian (brentq on B s^2 - 2 A s + A^2 = 0, written here from the sag formula of
`optics/biconic.py`), placed with the forward model's corneal surface frame (`eye.surfaces.biconic_cornea`,
the surface the glints are traced on), moved into the scene by the rigid transform fitted (Kabsch) to the
Features' own ground-truth points, projected, and fitted by a plain algebraic conic fit on 360 points.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.eye.surfaces import biconic_cornea, cornea_apex, cornea_centre, pupil_centre
from eyehil.emulator.forward import simulate
from eyehil.emulator.optics.conic import Conic
from eyehil.emulator.render.geometry import eye_outlines
from eyehil.emulator.scene import load_scene


def _toric_eye():
    eye = published_eyes()[:1]
    return eye.replace(
        anterior_radius=np.array([7.3]), anterior_radius_perp=np.array([8.3]), anterior_conic=np.array([-0.35]),
        anterior_conic_perp=np.array([0.1]), anterior_axis_deg=np.array([30.0]),
        cornea_tilt_deg=np.array([[6.0, -4.0]]), cornea_offset=np.array([[0.3, -0.2, 0.0]]),
        pupil_decentre=np.array([[0.4, 0.3]]),
    )


def _sag(x: float, y: float, cx: float, cy: float, kx: float, ky: float) -> float:
    """The biconic sag as the smaller root of B s^2 - 2 A s + A^2 = 0 (A = cx x^2 + cy y^2, B = kx cx^2 x^2 + ...)."""
    a, b = cx * x * x + cy * y * y, kx * cx * cx * x * x + ky * cy * cy * y * y
    if abs(b) < 1e-15:
        return a / 2.0
    upper = a / b if b > 0 else 10.0
    return brentq(lambda s: b * s * s - 2.0 * a * s + a * a, 0.0, upper * (1 - 1e-12), xtol=1e-14)


def _kabsch(local: np.ndarray, scene: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and shift t with scene = R local + t (least squares)."""
    lc, sc = local.mean(0), scene.mean(0)
    u, _, vt = np.linalg.svd((local - lc).T @ (scene - sc))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, sc - rot @ lc


def _conic_fit(px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre, full axes sorted major first) of the algebraic least-squares conic through px (N, 2)."""
    m = px.mean(0)
    x, y = (px - m).T
    design = np.column_stack([x * x, x * y, y * y, x, y, np.ones_like(x)])
    a, b, c, d, e, f = np.linalg.svd(design)[2][-1]
    quad = np.array([[a, b / 2], [b / 2, c]])
    centre = np.linalg.solve(2 * quad, [-d, -e])
    value = f + 0.5 * (d * centre[0] + e * centre[1])
    semi = np.sqrt(-value / np.linalg.eigvalsh(quad))
    return centre + m, np.sort(2 * semi)[::-1]


def _independent_limbus(features, eye_side, s: int, scene, n: int = 360) -> np.ndarray:
    """(H, T, n, 2) px of the corneal edge, computed as the module docstring says."""
    surface = biconic_cornea(eye_side)[0]
    r_l = float(eye_side.limbus_radius[0])
    cx, cy = 1 / float(surface.radius_x[0]), 1 / float(surface.radius_y[0])
    kx, ky = 1 + float(surface.conic_x[0]), 1 + float(surface.conic_y[0])
    t = 2 * np.pi * np.arange(n) / n
    xs, ys = r_l * np.cos(t), r_l * np.sin(t)
    sag = np.array([_sag(x, y, cx, cy, kx, ky) for x, y in zip(xs, ys, strict=True)])
    local = surface.vertex[0] + np.stack([xs, ys, -sag], -1) @ surface.rotation[0].T  # (n, 3) eye-local
    apex, centre, pupil = cornea_apex(eye_side)[0], cornea_centre(eye_side)[0], pupil_centre(eye_side)[0]
    known = np.stack([apex, centre, pupil, apex + np.array([0.0, 0.0, 1.0])])
    out = np.empty((*features.apex.shape[2:4], n, 2))
    for h in range(out.shape[0]):
        for k in range(out.shape[1]):
            seen = np.stack([features.apex[0, s, h, k], features.cornea_centre[0, s, h, k],
                             features.pupil_centre[0, s, h, k],
                             features.apex[0, s, h, k] + features.optic_axis[0, s, h, k]])
            rot, shift = _kabsch(known, seen)
            assert np.abs(known @ rot.T + shift - seen).max() < 1e-9  # a rigid pose explains the ground truth
            out[h, k] = scene.camera.project(local @ rot.T + shift)[0]
    return out


@pytest.mark.parametrize("scene_name", ["blignaut2014", "guestrin2006"])
def test_toric_limbus_matches_an_independent_trace(scene_name: str) -> None:
    scene = load_scene(scene_name)
    eye = _toric_eye()
    targets = scene.targets()[::17]
    features = simulate(eye, scene, targets=targets, head_positions=scene.head_positions[:2])
    outline = eye_outlines(features, eye, scene)
    worst_old = 0.0
    for s, side in enumerate(features.sides):
        eye_side = eye.with_laterality(side)
        expected = _independent_limbus(features, eye_side, s, scene)
        for h in range(expected.shape[0]):
            for k in range(expected.shape[1]):
                centre, axes = _conic_fit(expected[h, k])
                np.testing.assert_allclose(outline.limbus_centre_px[0, s, h, k], centre, atol=1e-5)
                np.testing.assert_allclose(outline.limbus_axes_px[0, s, h, k], axes, atol=0.01)  # not planar: 24 vs 360
                worst_old = max(worst_old, float(np.abs(_one_meridian_centre(features, eye, scene, 0, s, h, k)
                                                        - centre).max()))
    assert worst_old > 1.0  # the former limbus (one meridian, untilted) misses by more: the test can tell


def _one_meridian_centre(features, eyes, scene, e: int, s: int, h: int, k: int) -> np.ndarray:
    """Image centre of the former limbus: a circle at the sag of the first meridian about the optic axis."""
    eye = eyes[e:e + 1]
    axis, apex = features.optic_axis[e, s, h, k], features.apex[e, s, h, k]
    u = np.cross([0.0, 1.0, 0.0], axis)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    r_l = float(eye.limbus_radius[0])
    sag = float(Conic(0.0, eye.anterior_radius[0], eye.anterior_conic[0], 2 * r_l).sag(r_l**2)[0])
    t = 2 * np.pi * np.arange(360) / 360
    ring = apex - sag * axis + r_l * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * v)
    return _conic_fit(scene.camera.project(ring)[0])[0]


def test_a_cornea_of_revolution_keeps_its_circular_limbus() -> None:
    """For the published (rotationally symmetric) eyes the edge is the circle about the optic axis, as before."""
    scene = load_scene("blignaut2014")
    eyes = published_eyes()[:2]
    features = simulate(eyes, scene, targets=scene.targets()[::30], head_positions=scene.head_positions[:1])
    outline = eye_outlines(features, eyes, scene)
    for e in range(2):
        for s in range(len(features.sides)):
            for k in range(features.apex.shape[3]):
                np.testing.assert_allclose(outline.limbus_centre_px[e, s, 0, k],
                                           _one_meridian_centre(features, eyes, scene, e, s, 0, k), atol=1e-6)
