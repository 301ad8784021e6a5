"""Least-squares ellipse fit, batched: the direct method of Fitzgibbon, Pilu & Fisher (1999) in the
numerically stable form of Halir & Flusser (1998), with per-point weights (0 drops a point).

Conic a x^2 + b xy + c y^2 + d x + e y + f = 0 with 4ac - b^2 = 1: D1 = [x^2, xy, y^2], D2 = [x, y, 1],
S1 = D1'D1, S2 = D1'D2, S3 = D2'D2, T = -S3^-1 S2', M = C1^-1 (S1 + S2 T) with
C1^-1 = [[0, 0, 1/2], [0, -1, 0], [1/2, 0, 0]]; the eigenvector of M with 4 a c - b^2 > 0 is (a, b, c),
and (d, e, f) = T (a, b, c). Points are centred and scaled per ellipse first for conditioning.

Result per ellipse: centre (px), full axis lengths (major, minor) and the angle of the major axis in
degrees from image +x toward image +y (down), in [0, 180). Known answer: points on a circle of radius
r about (x0, y0) give centre (x0, y0) and axes (2r, 2r).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_POINTS = 5
C1_INV = np.array([[0.0, 0.0, 0.5], [0.0, -1.0, 0.0], [0.5, 0.0, 0.0]])


@dataclass(frozen=True)
class Ellipse:
    """Batched ellipse: centre (..., 2), axes (..., 2) full lengths major >= minor, angle_deg (...), valid."""

    centre: np.ndarray
    axes: np.ndarray
    angle_deg: np.ndarray
    valid: np.ndarray


def fit_ellipse(points: np.ndarray, weights: np.ndarray | None = None) -> Ellipse:
    """Fit one ellipse per batch element to points (..., N, 2); `weights` (..., N) drop points with 0."""
    w = np.ones(points.shape[:-1]) if weights is None else np.asarray(weights, dtype=float)
    enough = np.count_nonzero(w > 0, axis=-1) >= MIN_POINTS
    wsum = np.maximum(w.sum(axis=-1, keepdims=True), 1e-300)
    mean = np.einsum("...n,...nk->...k", w, np.nan_to_num(points)) / wsum
    centred = np.nan_to_num(points - mean[..., None, :])
    scale = np.sqrt(np.einsum("...n,...nk->...", w, centred**2) / wsum[..., 0])
    scale = np.where(scale > 0, scale, 1.0)
    x, y = np.moveaxis(centred / scale[..., None, None], -1, 0)
    sw = np.sqrt(w)
    d1 = np.stack([x * x, x * y, y * y], axis=-1) * sw[..., None]
    d2 = np.stack([x, y, np.ones_like(x)], axis=-1) * sw[..., None]
    s1, s2, s3 = (np.swapaxes(a, -1, -2) @ b for a, b in ((d1, d1), (d1, d2), (d2, d2)))
    s3 = s3 + np.eye(3) * 1e-300
    with np.errstate(all="ignore"):
        t = -np.linalg.solve(np.where(enough[..., None, None], s3, np.eye(3)), np.swapaxes(s2, -1, -2))
        m = C1_INV @ (s1 + s2 @ t)
        _, vecs = np.linalg.eig(np.where(np.isfinite(m), m, 0.0))
    vecs = vecs.real
    cond = 4 * vecs[..., 0, :] * vecs[..., 2, :] - vecs[..., 1, :] ** 2
    pick = np.argmax(np.where(cond > 0, cond, -np.inf), axis=-1)
    a1 = np.take_along_axis(vecs, pick[..., None, None], axis=-1)[..., 0]
    conic = np.concatenate([a1, (t @ a1[..., None])[..., 0]], axis=-1)
    centre, axes, angle, ok = _conic_to_ellipse(conic)
    centre = centre * scale[..., None] + mean
    valid = enough & ok & np.any(cond > 0, axis=-1)
    return Ellipse(centre=centre, axes=axes * scale[..., None], angle_deg=angle, valid=valid)


def _conic_to_ellipse(k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    k = k * np.where(k[..., 0:1] < 0, -1.0, 1.0)  # a > 0 so that the quadratic form is positive definite
    a, b, c, d, e, f = np.moveaxis(k, -1, 0)
    with np.errstate(all="ignore"):
        den = 4 * a * c - b * b
        x0 = (b * e - 2 * c * d) / den
        y0 = (b * d - 2 * a * e) / den
        f0 = f + (d * x0 + e * y0) / 2
        root = np.sqrt((a - c) ** 2 + b * b)
        lam_small, lam_big = (a + c - root) / 2, (a + c + root) / 2
        major = 2 * np.sqrt(-f0 / lam_small)
        minor = 2 * np.sqrt(-f0 / lam_big)
        angle = np.degrees(0.5 * np.arctan2(b, a - c)) + 90.0  # direction of the smaller eigenvalue
    ok = (den > 0) & np.isfinite(major) & np.isfinite(minor) & (major > 0) & (minor > 0)
    return np.stack([x0, y0], axis=-1), np.stack([major, minor], axis=-1), np.mod(angle, 180.0), ok
