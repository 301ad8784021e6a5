"""Robust ellipse fitting of pupil edge points for `eyehil.drivers.detect` (OpenCV + numpy, image px).

`robust_ellipse(points)`: a direct least-squares ellipse (`cv2.fitEllipseDirect`, Fitzgibbon et al.
1999) refitted `refits` times on the points within [-`inlier_px`, max(`inlier_px`, 3 robust sigma)] of it
(Sampson distance, + outside). Trimming is asymmetric because an occluder (eyelid, lashes) always cuts
the pupil: its edge points lie inside the true outline. When fewer than `good_fraction` of the points end
up within `score_px` of the fit (an eyelid edge the brightness test did not remove), contiguous arcs of
60, 120 and 180 deg (every 30 deg about the points' centroid) are left out, one fit each, and the one with
the most points within `score_px` is refined as above: a RANSAC over the hypotheses an occluding lid
makes. Result: centre (2,), full axes (a >= b), angle
of a in deg from image +x toward +y in [0, 180), support (fraction of 36 sectors holding inliers), inlier
rms (px); or the name of a failure.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

SECTORS = 36


@dataclass(frozen=True)
class EllipseFit:
    """An ellipse fitted to edge points (px, deg) with its support and inlier rms (px)."""

    centre: np.ndarray
    axes: np.ndarray
    angle: float
    support: float
    rms: float
    inliers: int


def robust_ellipse(points: np.ndarray, *, inlier_px: float = 0.6, refits: int = 3, min_points: int = 12,
                   score_px: float = 0.25, good_fraction: float = 0.9) -> EllipseFit | str:
    """The ellipse of the module docstring, or "too_few_edge_points" / "ellipse_fit_failed"."""
    if len(points) < min_points:
        return "too_few_edge_points"
    best = _trimmed(points, np.ones(len(points), bool), inlier_px, refits, min_points, score_px)
    if best is None or best.inliers < good_fraction * len(points):
        angle = np.degrees(np.arctan2(*(points - points.mean(axis=0)).T[::-1]))
        chosen = None
        for width in (60, 120, 180):
            for start in range(0, 360, 30):
                keep = np.mod(angle - start, 360.0) >= width
                fit = _trimmed(points, keep, inlier_px, 0, min_points, score_px)
                if fit is not None and (best is None or fit.inliers > best.inliers):
                    best, chosen = fit, keep
        if chosen is not None:
            best = _trimmed(points, chosen, inlier_px, refits, min_points, score_px) or best
    return "ellipse_fit_failed" if best is None else best


def _trimmed(points: np.ndarray, keep: np.ndarray, inlier_px: float, refits: int, min_points: int, score_px: float):
    """Fit on `keep`, then refit on the asymmetric inlier band; None if too few points or no ellipse."""
    for _ in range(refits + 1):
        if np.count_nonzero(keep) < min_points:
            return None
        (cx, cy), (w, h), angle = cv2.fitEllipseDirect(points[keep])
        if not (np.isfinite([cx, cy, w, h]).all() and w > 0 and h > 0):
            return None
        axes, angle = (np.array([w, h]), angle) if w >= h else (np.array([h, w]), angle + 90.0)
        d, phase = sampson(points, np.array([cx, cy]), axes, angle)
        sigma = 1.4826 * np.median(np.abs(d[keep]))
        kept, keep = keep, (d >= -max(score_px, 2.0 * sigma)) & (d <= max(inlier_px, 3.0 * sigma))
        if np.array_equal(kept, keep):
            break
    inliers = np.abs(d) <= score_px
    if not np.any(inliers):
        return None
    support = len(np.unique((phase[inliers] / (2 * np.pi) * SECTORS).astype(int) % SECTORS)) / SECTORS
    rms = float(np.sqrt(np.mean(d[inliers] ** 2)))
    return EllipseFit(np.array([cx, cy]), axes, float(angle % 180.0), support, rms, int(np.count_nonzero(inliers)))


def sampson(points: np.ndarray, centre: np.ndarray, axes: np.ndarray, angle_deg: float,
            ) -> tuple[np.ndarray, np.ndarray]:
    """First-order signed distance (px, + outside) of points (N, 2) to an ellipse (centre, full axes, angle
    deg), and each point's angle about the ellipse (rad, [0, 2 pi))."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    dx, dy = (points - centre).T
    a, b = axes / 2
    u, v = (dx * c + dy * s) / a, (-dx * s + dy * c) / b
    f = np.hypot(u, v)
    grad = np.hypot(u / a, v / b)
    return (f - 1.0) * f / np.maximum(grad, 1e-12), np.mod(np.arctan2(v, u), 2 * np.pi)
