"""Pixel drawing of one eye into a float32 radiance canvas (used by `eyehil.emulator.render.renderer`).

Canvas: a window of the sensor whose top-left pixel is the sensor pixel (x0, y0); canvas[i, j] is the
sensor pixel (x0 + j, y0 + i); coordinates are full-sensor px (OpenCV convention). Radiance in DN at the
sensor's exposure and gain, before blur, noise and saturation.

Layers, each an anti-aliased coverage in [0, 1] (0.5 + signed distance to the boundary in px, clipped):
aperture A between the lids, limbus L (the projected corneal edge), pupil P (the dense ray-traced
outline); radiance = skin + A (sclera - skin + L (iris - sclera + P (pupil - iris))), then glints
A * E g(x) with g a Gaussian of `glint_sigma_px` integrated over each pixel (erf differences) and E
the energy that gives a peak of `glint_peak_dn` after the defocus blur; optional eyelashes are dark
anti-aliased strokes from the upper margin. Only the bounding boxes of the features are evaluated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import erf

from eyehil.emulator.render.geometry import EyeOutline, aperture_coverage, clip_unit
from eyehil.emulator.render.noise import Noise, generator_of

Box = tuple[int, int, int, int]  # canvas rows [r0, r1), columns [c0, c1)


@dataclass(frozen=True)
class Levels:
    """Radiances (DN) of the layers at the sensor's exposure and gain; glint size and lashes."""

    pupil: float
    iris: float
    sclera: float
    skin: float
    lash: float
    glint_peak: float
    glint_sigma_px: float
    blur_sigma_px: float
    lashes: int
    lash_length_mm: float
    traced_pupil: bool = True  # draw the dense ray-traced outline; False: its fitted ellipse


def box_of(x_lo: float, x_hi: float, y_lo: float, y_hi: float, origin: tuple[int, int], size: tuple[int, int],
           margin: float = 2.0) -> Box | None:
    """Canvas box covering sensor px [x_lo, x_hi] x [y_lo, y_hi] plus `margin`, or None if off the canvas."""
    x_lo, x_hi, y_lo, y_hi = float(x_lo), float(x_hi), float(y_lo), float(y_hi)
    if not (math.isfinite(x_lo) and math.isfinite(x_hi) and math.isfinite(y_lo) and math.isfinite(y_hi)):
        return None
    (x0, y0), (w, h) = origin, size
    c0, c1 = max(math.floor(x_lo - margin) - x0, 0), min(math.ceil(x_hi + margin) - x0 + 1, w)
    r0, r1 = max(math.floor(y_lo - margin) - y0, 0), min(math.ceil(y_hi + margin) - y0 + 1, h)
    return (r0, r1, c0, c1) if r1 > r0 and c1 > c0 else None


def eye_box(o: EyeOutline, levels: Levels, origin: tuple[int, int], size: tuple[int, int]) -> Box | None:
    """The canvas box of one eye's aperture (lids), widened by the blur and glint footprint."""
    lids = np.concatenate([o.upper_lid_px, o.lower_lid_px])
    margin = 4.0 * max(levels.blur_sigma_px, levels.glint_sigma_px) + 3.0
    return box_of(lids[:, 0].min(), lids[:, 0].max(), lids[:, 1].min(), lids[:, 1].max(), origin, size, margin)


def draw_eye(canvas: np.ndarray, origin: tuple[int, int], o: EyeOutline, levels: Levels,
             rng: Noise) -> Box | None:
    """Draw one eye sample `o` into `canvas` (radiance, DN); return the box drawn (None if off the canvas)."""
    box = eye_box(o, levels, origin, canvas.shape[::-1])
    if box is None:
        return None
    r0, r1, c0, c1 = box
    x = np.arange(c0, c1, dtype=np.float32) + origin[0]
    y = (np.arange(r0, r1, dtype=np.float32) + origin[1])[:, None]
    aperture = aperture_coverage(x, y, o.upper_lid_px, o.lower_lid_px)
    region = canvas[r0:r1, c0:c1]
    region += aperture * (levels.sclera - levels.skin)
    inner = _draw_limbus(region, aperture, x, y, o, levels)
    if inner is not None and o.pupil_valid:
        _draw_pupil(region, inner, x, y, o, levels)
    _draw_glints(region, aperture, x, y, o, levels)
    if levels.lashes:
        _draw_lashes(region, (x[0], y[0, 0]), o, levels, rng)
    return box


def _sub(x: np.ndarray, y: np.ndarray, centre: np.ndarray, half: float) -> tuple[slice, slice] | None:
    """Row and column slices of the region whose pixels lie within `half` px of `centre`; x (W,) and y (H, 1) are
    consecutive pixel coordinates (steps of 1 px)."""
    cx, cy, half = float(centre[0]), float(centre[1]), float(half)
    if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(half)):
        return None
    cols = _within(float(x[0]), len(x), cx, half)
    rows = _within(float(y[0, 0]), len(y), cy, half)
    return None if cols is None or rows is None else (rows, cols)


def _within(first: float, n: int, centre: float, half: float) -> slice | None:
    """The indices j in [0, n) with |first + j - centre| <= half, as a slice (None if there are none)."""
    lo, hi = max(math.ceil(centre - half - first), 0), min(math.floor(centre + half - first), n - 1)
    return slice(lo, hi + 1) if lo <= hi else None


def _draw_limbus(region, aperture, x, y, o: EyeOutline, levels: Levels):
    """Add the iris inside the limbus; return (slices, A * L on them) for the pupil, or None."""
    sl = _sub(x, y, o.limbus_centre_px, o.limbus_axes_px[0] / 2 + 2.0)
    if sl is None:
        return None
    rows, cols = sl
    cover = ellipse_coverage(x[cols], y[rows], o.limbus_centre_px, o.limbus_axes_px, o.limbus_angle_deg)
    weight = aperture[rows, cols] * cover
    region[rows, cols] += weight * (levels.iris - levels.sclera)
    return rows, cols, weight


def _draw_pupil(region, inner, x, y, o: EyeOutline, levels: Levels) -> None:
    rows, cols, weight = inner
    sl = _sub(x[cols], y[rows], o.pupil_centre_px, float(np.max(o.pupil_r)) + 2.0)
    if sl is None:
        return
    pr, pc = sl
    if levels.traced_pupil:
        cover = polar_coverage(x[cols][pc], y[rows][pr], o.pupil_centre_px, o.pupil_theta, o.pupil_r, o.pupil_dr)
    else:
        cover = ellipse_coverage(x[cols][pc], y[rows][pr], o.pupil_centre_px, o.pupil_axes_px, o.pupil_angle_deg)
    region[rows, cols][pr, pc] += weight[pr, pc] * cover * (levels.pupil - levels.iris)


def ellipse_coverage(x: np.ndarray, y: np.ndarray, centre: np.ndarray, axes: np.ndarray, angle_deg: float):
    """Coverage (H, W) of the ellipse (centre px, full axes px, angle deg) at x (W,), y (H, 1), float32."""
    c, s = float(np.cos(np.radians(angle_deg))), float(np.sin(np.radians(angle_deg)))
    a, b = float(axes[0]) / 2, float(axes[1]) / 2
    dx, dy = x - np.float32(centre[0]), y - np.float32(centre[1])
    u, v = (dx * (c / a) + dy * (s / a)), (dy * (c / b) - dx * (s / b))
    f = np.sqrt(u * u + v * v)
    grad = np.sqrt(np.square(u / a) + np.square(v / b))
    distance = (f - 1.0) * f / np.maximum(grad, 1e-9)
    return clip_unit(np.subtract(0.5, distance, out=distance))


def polar_coverage(x, y, centre, theta, r, dr) -> np.ndarray:
    """Coverage (H, W) of the star-shaped outline r(theta) about `centre` at x (W,), y (H, 1).

    Signed distance (rho - r(theta)) r / sqrt(r^2 + r'^2): the radial excess times the cosine between the
    radial direction and the outline's normal; evaluated only in the annulus min(r) - 1 <= rho <= max(r) + 1
    (1 inside it, 0 outside). r and r' are interpolated linearly between the sorted angles `theta`, around the
    circle (`periodic_lerp`)."""
    dx, dy = (x - centre[0]).astype(np.float32), (y - centre[1]).astype(np.float32)
    rho = np.sqrt(dx * dx + dy * dy)
    r_in, r_out = float(np.min(r)), float(np.max(r))
    cover = (rho < r_in).astype(np.float32)
    rows, cols = np.nonzero((rho >= r_in - 1.0) & (rho <= r_out + 1.0))
    phi = np.arctan2(dy[rows, 0], dx[cols])
    radius, slope = periodic_lerp(phi, theta, np.stack([r, dr]))
    distance = (rho[rows, cols] - radius) * radius / np.sqrt(radius**2 + slope**2)
    cover[rows, cols] = clip_unit(0.5 - distance)
    return cover


def periodic_lerp(phi: np.ndarray, theta: np.ndarray, table: np.ndarray) -> np.ndarray:
    """The rows of `table` (k, m), given at the ascending angles `theta` (m,) rad within one turn, interpolated
    linearly at `phi` (...,) rad in [-pi, pi] and around the circle (`np.interp` with period 2 pi, one search for
    all rows): (k, ...)."""
    turn = 2.0 * np.pi
    angles = np.concatenate(([theta[-1] - turn], theta, [theta[0] + turn]))
    values = np.concatenate((table[:, -1:], table, table[:, :1]), axis=1)
    upper = np.minimum(np.maximum(np.searchsorted(angles, phi, side="right"), 1), len(angles) - 1)
    start, span = angles[upper - 1], angles[upper] - angles[upper - 1]
    weight = (phi - start) / np.where(span > 0, span, np.inf)
    low = values[:, upper - 1]
    return low + weight * (values[:, upper] - low)


def _draw_glints(region, aperture, x, y, o: EyeOutline, levels: Levels) -> None:
    sigma = levels.glint_sigma_px
    energy = levels.glint_peak * 2.0 * np.pi * (sigma**2 + levels.blur_sigma_px**2)
    for (gx, gy), ok in zip(o.glint_px, o.glint_valid, strict=True):
        sl = _sub(x, y, np.array([gx, gy]), 4.0 * sigma + 2.0) if ok else None
        if sl is None:
            continue
        rows, cols = sl
        wx = _pixel_gauss(x[cols] - gx, sigma)
        wy = _pixel_gauss(y[rows, 0] - gy, sigma)
        region[rows, cols] += energy * aperture[rows, cols] * np.outer(wy, wx).astype(np.float32)


def _pixel_gauss(d: np.ndarray, sigma: float) -> np.ndarray:
    """A unit-area Gaussian of `sigma` px integrated over pixels whose centres are at offsets d (px)."""
    k = 1.0 / (np.sqrt(2.0) * sigma)
    return 0.5 * (erf((d + 0.5) * k) - erf((d - 0.5) * k))


def _draw_lashes(region, corner, o: EyeOutline, levels: Levels, noise: Noise) -> None:
    """Dark strokes from random points of the middle of the upper margin, hanging 30 to 60 % of their length."""
    n = levels.lashes
    lid = o.upper_lid_px
    rng = generator_of(noise)
    k = rng.uniform(0.2, 0.8, n) * (len(lid) - 1)
    root = np.array([np.interp(k, np.arange(len(lid)), lid[:, i]) for i in (0, 1)]).T
    angle = rng.uniform(np.radians(60), np.radians(120), n)
    length = levels.lash_length_mm * o.px_per_mm * rng.uniform(0.3, 0.6, n)
    tip = root + length[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    mask = np.zeros(region.shape, np.uint8)
    shift = 4  # cv2 fixed-point sub-pixel bits
    for a, b in zip(root - corner, tip - corner, strict=True):
        if np.all(np.isfinite([*a, *b])):
            cv2.line(mask, tuple(np.round(a * 16).astype(int)), tuple(np.round(b * 16).astype(int)), 255, 1,
                     cv2.LINE_AA, shift)
    alpha = mask.astype(np.float32) / 255.0
    region += alpha * (levels.lash - region)
