"""Glints for `eyehil.drivers.detect`: candidates near the pupil, sub-pixel centres, LEDs matched by geometry.

Image px of the window (OpenCV convention); returned glints are shifted to full-sensor px by `roi_xy`.

Candidates: outer contours of the pixels >= `glint_level` x saturation within `glint_search` pupil radii
of the pupil centre, of at most `glint_max_area_px` and a bounding box no more elongated than 3:1; the
`n_leds` largest are kept.

Centre: a Gauss-Newton fit (<= 8 steps, Cholesky) of min(B + A exp(-r^2 / 2 s^2), saturation) to the pixels
within `glint_guard_px` of the candidate, where saturated pixels only bound the model from below
(censored). The background B under the glint is filled from the ring of pixels around it by a
cross-bilateral average: ring pixels weigh exp(-dd^2 / 2 (0.5 px)^2 - dr^2 / 2 (2 px)^2), with dd the
difference in signed distance to the pupil ellipse and dr the distance in the image. So B follows the
pupil edge across a glint that straddles it (0.01 to 0.03 px RMS on synthetic frames, where centroids of
thresholded intensity reach 0.12 px near the pupil edge; docs/frames.md).

LED matching: glints and LEDs are ordered along the direction of the LED layout (its principal axis in
(world x, -world y)); the scenes' cameras face the subject with image x along world +x and image y along
world -y, so an LED at larger world x makes a glint at larger image x. Without LED positions, LED k makes
the k-th glint from the left. With fewer candidates than LEDs, those found are reported AMBIGUOUS (not
VALID), assigned by rank.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from eyehil.drivers.detect.ellipse import sampson
from eyehil.protocols.enums import GlintFlags
from eyehil.protocols.samples import Glint

if TYPE_CHECKING:
    from eyehil.drivers.detect import DetectorSettings


@dataclass(frozen=True)
class PupilEllipse:
    """Pupil ellipse in window px: centre (2,), full axes (a >= b), angle of a (deg)."""

    centre: np.ndarray
    axes: np.ndarray
    angle: float


def disk(r: int) -> np.ndarray:
    """A filled disk structuring element of radius `r` px."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def find_glints(img: np.ndarray, pupil: PupilEllipse, n_leds: int, led_xy: np.ndarray | None, s: DetectorSettings,
                roi_xy: tuple[int, int] = (0, 0)) -> tuple[list[Glint], str | None]:
    """The glints of one eye, by LED, in full-sensor px; the failure "glint_missing" if too few were found."""
    r = s.glint_search * pupil.axes[0] / 2
    x0, y0 = max(int(pupil.centre[0] - r), 0), max(int(pupil.centre[1] - r), 0)
    raw = img[y0:int(pupil.centre[1] + r) + 2, x0:int(pupil.centre[0] + r) + 2]
    _, mask = cv2.threshold(raw, float(np.ceil(s.glint_level * s.saturation_dn)) - 1.0, 255, cv2.THRESH_BINARY)
    found = _candidates(mask, pupil.centre - (x0, y0), r, s.glint_max_area_px)[:n_leds]
    guard = cv2.dilate(mask, disk(s.glint_guard_px))
    crop = raw.astype(np.float32)
    local = PupilEllipse(pupil.centre - (x0, y0), pupil.axes, pupil.angle)
    fits = [_fit_glint(crop, box, comp, guard, local, s) for box, comp in found]
    leds = match_leds(np.array([f[:2] for f in fits]).reshape(-1, 2), n_leds, led_xy)
    missing = len(fits) < n_leds
    glints = [Glint(int(led), float(x + x0 + roi_xy[0]), float(y + y0 + roi_xy[1]),
                    GlintFlags.AMBIGUOUS if missing else flags) for (x, y, flags), led in zip(fits, leds, strict=True)]
    return sorted(glints, key=lambda g: g.led), "glint_missing" if missing else None


def _candidates(mask: np.ndarray, centre: np.ndarray, radius: float, max_area: int) -> list:
    """[(bounding box (x, y, w, h), filled component (h, w) uint8)] of plausible glints, largest first."""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    out = []
    for c in contours:
        x, y, w, h = cv2.boundingRect(c)
        if np.hypot(x + (w - 1) / 2 - centre[0], y + (h - 1) / 2 - centre[1]) > radius or max(w, h) > 3 * min(w, h) + 2:
            continue
        comp = np.zeros((h, w), np.uint8)
        cv2.drawContours(comp, [c], -1, 1, -1, offset=(-x, -y))
        if np.count_nonzero(comp) <= max_area:
            out.append(((x, y, w, h), comp))
    return sorted(out, key=lambda item: -np.count_nonzero(item[1]))


def match_leds(xy: np.ndarray, n_leds: int, led_xy: np.ndarray | None) -> np.ndarray:
    """LED index of each glint (N, 2) px, both sets ordered along the LED layout (module docstring)."""
    direction, led_key = np.array([1.0, 0.0]), np.arange(n_leds, dtype=float)
    if led_xy is not None and n_leds >= 2:
        leds = np.asarray(led_xy, float)[:, :2] * (1.0, -1.0)
        centred = leds - leds.mean(axis=0)
        if np.any(centred):
            direction = np.linalg.svd(centred)[2][0]
            direction = direction if direction @ (1.0, 1e-3) >= 0 else -direction
        led_key = leds @ direction
    led_order = np.argsort(led_key, kind="stable")
    rank = np.argsort(np.argsort(xy @ direction, kind="stable"), kind="stable")
    if len(xy) < n_leds:
        rank = np.round(rank * (n_leds - 1) / max(len(xy) - 1, 1)).astype(int)
    return led_order[rank]


def _fit_glint(crop: np.ndarray, box, comp: np.ndarray, guard: np.ndarray, pupil: PupilEllipse,
               s: DetectorSettings) -> tuple[float, float, GlintFlags]:
    """(x, y, flags) crop px of one candidate: the censored Gaussian fit of the module docstring."""
    x, y, w, h = box
    pad = s.glint_guard_px + 3
    r0, c0 = max(y - pad, 0), max(x - pad, 0)
    win = crop[r0:y + h + pad, c0:x + w + pad]
    sl = (slice(r0, r0 + win.shape[0]), slice(c0, c0 + win.shape[1]))
    own = np.zeros(win.shape, np.uint8)
    own[y - r0:y - r0 + h, x - c0:x - c0 + w] = comp
    own = cv2.dilate(own, disk(s.glint_guard_px))
    ring = (cv2.dilate(own, disk(2)) > 0) & (guard[sl] == 0)
    yy, xx = np.mgrid[sl]
    d = sampson(np.stack([xx.ravel(), yy.ravel()], -1), pupil.centre, pupil.axes, pupil.angle)[0].reshape(win.shape)
    inside = own > 0
    px, py = xx[inside].astype(float), yy[inside].astype(float)
    background = _background(np.stack([xx[ring], yy[ring]], -1), d[ring], win[ring], np.stack([px, py], -1), d[inside])
    values = win[inside].astype(float)
    cx, cy = _gauss_fit(px, py, values, background, s.saturation_dn)
    flags = GlintFlags.VALID
    if values.max() >= s.saturation_dn - 0.5:
        flags |= GlintFlags.SATURATED
    if np.min(np.abs(d[inside])) < 1.0:
        flags |= GlintFlags.ON_PUPIL_EDGE
    return cx, cy, flags


def _background(ring_xy: np.ndarray, ring_d: np.ndarray, value: np.ndarray, at_xy: np.ndarray,
                at_d: np.ndarray) -> np.ndarray:
    """Background at `at_xy` (signed pupil-edge distances `at_d`): the cross-bilateral fill of the docstring."""
    if ring_d.size == 0:
        return np.zeros(len(at_d))
    exponent = 2.0 * np.square(at_d[:, None] - ring_d)  # (dd / 0.5 px)^2 / 2
    exponent += (np.square(at_xy[:, :1] - ring_xy[:, 0]) + np.square(at_xy[:, 1:] - ring_xy[:, 1])) / 8.0
    w = np.exp(-exponent)
    return (w @ value + 1e-12 * value.mean()) / (w.sum(axis=1) + 1e-12)


def _gauss_fit(x: np.ndarray, y: np.ndarray, value: np.ndarray, background: np.ndarray, saturation: float,
               steps: int = 8) -> tuple[float, float]:
    """Centre (px) of min(B + A exp(-r^2 / 2 s^2), saturation) fitted to pixels (x, y, value) over B.

    Pixels where the model is clipped have no gradient; saturated pixels contribute only while the model
    is below saturation. Falls back to the excess-weighted centroid if the fit wanders over 2 px."""
    excess = np.maximum(value - background, 0.0)
    start = np.array([excess @ x, excess @ y]) / max(excess.sum(), 1e-9)
    cx, cy, ln_a, ln_s = start[0], start[1], np.log(max(excess.max(), 1.0) * 3.0), 0.0
    target = np.where(value >= saturation - 0.5, saturation, value) - background
    limit = saturation - background
    jac = np.empty((4, len(x)))
    for _ in range(steps):
        inv = np.exp(-2.0 * ln_s)
        dx, dy = x - cx, y - cy
        r2 = dx * dx + dy * dy
        g = np.exp(ln_a - 0.5 * inv * r2)
        g *= g < limit  # clipped model pixels have no gradient
        jac[0], jac[1], jac[2], jac[3] = g * dx * inv, g * dy * inv, g, g * r2 * inv
        h = jac @ jac.T
        h[np.diag_indices(4)] *= 1.0 + 1e-6
        ok, step = cv2.solve(h, (jac @ (target - g))[:, None], flags=cv2.DECOMP_CHOLESKY)
        if not ok:
            break
        step = step[:, 0]
        cx, cy = cx + step[0], cy + step[1]
        ln_a, ln_s = min(max(ln_a + step[2], 0.0), 12.0), min(max(ln_s + step[3], -1.5), 1.5)
        if abs(step[0]) + abs(step[1]) < 1e-3:
            break
    if np.hypot(cx - start[0], cy - start[1]) >= 2.0:
        cx, cy = start
    return float(cx), float(cy)
