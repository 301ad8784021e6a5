"""An independent analytic forward model of a spherical-cornea eye, for testing the host estimators.

World frame as in `eyehil.drivers.gaze.geometry` (mm; x to the subject's left, y up, z toward the screen).
The eye: a corneal sphere of radius R centred at c; the pupil centre p = c + K w on the optic axis w;
c = E + d w with E the centre of rotation. Axes by the angle-addition form of Guestrin & Eizenman 2006:
w = [cos(phi) sin(theta), sin(phi), cos(phi) cos(theta)] and the visual axis through c,
nu = [cos(phi+beta) sin(theta+alpha), sin(phi+beta), cos(phi+beta) cos(theta+alpha)].

Glints and the pupil image are solved here by bisection on an angle in the plane of the relevant
points (normal bisecting the LED and camera directions; Snell's law n1 sin i = n2 sin t), not by
the estimator's formulas, and projected with a plain pinhole.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.drivers.gaze.base import EyeSamples
from eyehil.drivers.gaze.geometry import Camera, Screen, TrackerGeometry

GUESTRIN_CAMERA_O = np.array([0.0, -150.5, 615.0])
RIGHT_APEX = np.array([-31.5, 0.0, 0.0])


def guestrin_geometry() -> TrackerGeometry:
    """The Guestrin 2006 scene in the world frame (camera looking at the origin's height)."""
    K = np.array([[4666.67, 0.0, 320.0], [0.0, 4666.67, 240.0], [0.0, 0.0, 1.0]])
    camera = Camera.look_at(GUESTRIN_CAMERA_O, np.zeros(3), K, (640, 480))
    leds = np.array([[188.5, 0.0, 650.0], [-188.5, 0.0, 650.0]])
    return TrackerGeometry(camera=camera, leds=leds, screen=Screen(centre=(0.0, 0.0, 650.0), size_mm=(377.0, 301.0)))


@dataclass(frozen=True)
class SphericalEye:
    """Parameters (mm, deg) of a spherical-cornea eye; `d` = |c - E| (rotation centre to corneal centre)."""

    R: float = 7.8
    K: float = 4.2
    alpha_deg: float = 5.0
    beta_deg: float = 1.5
    n1: float = 1.3375
    d: float = 5.5

    def rotation_centre(self, apex: np.ndarray) -> np.ndarray:
        """E for an eye whose unrotated (optic axis = +z) corneal apex is at `apex`."""
        return np.asarray(apex, float) - np.array([0.0, 0.0, self.R + self.d])


def _axis(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(phi) * np.sin(theta), np.sin(phi), np.cos(phi) * np.cos(theta)], axis=-1)


def fixate(eye: SphericalEye, centre: np.ndarray, targets_world: np.ndarray, iterations: int = 80):
    """Corneal centre c and optic axis w (..., 3) of the eye rotated so its visual axis hits the targets."""
    alpha, beta = np.radians(eye.alpha_deg), np.radians(eye.beta_deg)
    targets = np.asarray(targets_world, float)
    theta = np.zeros(targets.shape[:-1])
    phi = np.zeros(targets.shape[:-1])
    for _ in range(iterations):
        c = centre + eye.d * _axis(theta, phi)
        u = targets - c
        u = u / np.linalg.norm(u, axis=-1, keepdims=True)
        theta, phi = np.arctan2(u[..., 0], u[..., 2]) - alpha, np.arcsin(u[..., 1]) - beta
    w = _axis(theta, phi)
    return centre + eye.d * w, w


def _plane_basis(c: np.ndarray, toward: np.ndarray, other: np.ndarray):
    """Orthonormal in-plane basis (a toward `toward`, b toward `other`) and the angle of `other` from a."""
    a = toward - c
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    rel = other - c
    b = rel - np.sum(rel * a, -1, keepdims=True) * a
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    fallback = _unit(np.cross(a, [0.0, 1.0, 0.0]))
    b = np.where(nb > 1e-12, b / np.where(nb > 1e-12, nb, 1.0), fallback)
    return a, b, np.arctan2(np.sum(rel * b, -1), np.sum(rel * a, -1))


def _bisect(g, lo: np.ndarray, hi: np.ndarray, iterations: int = 200) -> np.ndarray:
    """Root of g in [lo, hi] (elementwise), given g(lo) and g(hi) of opposite signs."""
    g_lo = g(lo)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        same = np.sign(g(mid)) == np.sign(g_lo)
        lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
    return 0.5 * (lo + hi)


def _cross2(n: np.ndarray, s: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Signed 2-D cross product of in-plane vectors n and s in the basis (a, b)."""
    return np.sum(n * a, -1) * np.sum(s * b, -1) - np.sum(n * b, -1) * np.sum(s * a, -1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def glint_point(c: np.ndarray, R: float, led: np.ndarray, o: np.ndarray) -> np.ndarray:
    """Reflection point q on the sphere: the normal (q - c)/R bisects the directions to LED and camera."""
    a, b, gamma = _plane_basis(c, o, led)

    def point(t):
        return c + R * (np.cos(t)[..., None] * a + np.sin(t)[..., None] * b)

    def g(t):
        q = point(t)
        n = (q - c) / R
        return _cross2(n, _unit(led - q) + _unit(o - q), a, b)

    return point(_bisect(g, np.zeros_like(gamma), gamma))


def pupil_image_point(c: np.ndarray, p: np.ndarray, R: float, n1: float, o: np.ndarray) -> np.ndarray:
    """Exit point r on the sphere of the ray from p that refracts (n1 -> 1) toward the camera at o."""
    a, b, psi = _plane_basis(c, o, p)

    def point(t):
        return c + R * (np.cos(t)[..., None] * a + np.sin(t)[..., None] * b)

    def g(t):
        r = point(t)
        n = (r - c) / R
        return n1 * _cross2(n, _unit(r - p), a, b) - _cross2(n, _unit(o - r), a, b)

    return point(_bisect(g, np.zeros_like(psi), psi))


def pinhole(camera: Camera, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates of world points: (u, v) = (f_x X/Z + c_x, f_y Y/Z + c_y), X_c = R (X - o)."""
    xc = np.einsum("ij,...j->...i", camera.R, points - camera.o)
    fx, fy, cx, cy = camera.K[0, 0], camera.K[1, 1], camera.K[0, 2], camera.K[1, 2]
    return np.stack([fx * xc[..., 0] / xc[..., 2] + cx, fy * xc[..., 1] / xc[..., 2] + cy], axis=-1)


@dataclass(frozen=True)
class Fixations:
    """Forward-model output: samples plus ground truth (world mm)."""

    samples: EyeSamples
    c: np.ndarray
    p: np.ndarray
    targets_world: np.ndarray


def simulate(eye: SphericalEye, geometry: TrackerGeometry, apex: np.ndarray, targets_mm: np.ndarray) -> Fixations:
    """Features of `eye` (unrotated apex at `apex`) fixating screen targets (..., 2) mm."""
    targets_world = geometry.screen.to_world(targets_mm)
    c, w = fixate(eye, eye.rotation_centre(apex), targets_world)
    p = c + eye.K * w
    o = geometry.camera.o
    glints = np.stack([pinhole(geometry.camera, glint_point(c, eye.R, led, o)) for led in geometry.leds], axis=-2)
    pupil = pinhole(geometry.camera, pupil_image_point(c, p, eye.R, eye.n1, o))
    return Fixations(EyeSamples(pupil, glints), c, p, targets_world)
