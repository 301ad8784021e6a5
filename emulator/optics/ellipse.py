"""Least-squares ellipse fit, batched: the direct method of Fitzgibbon, Pilu & Fisher (1999) in the
numerically stable form of Halir & Flusser (1998), with per-point weights (0 drops a point).

Conic a x^2 + b xy + c y^2 + d x + e y + f = 0 with 4ac - b^2 = 1: D1 = [x^2, xy, y^2], D2 = [x, y, 1],
S1 = D1'D1, S2 = D1'D2, S3 = D2'D2, T = -S3^-1 S2', M = C1^-1 (S1 + S2 T) with
C1^-1 = [[0, 0, 1/2], [0, -1, 0], [1/2, 0, 0]]; the eigenvector of M with 4 a c - b^2 > 0 is (a, b, c),
and (d, e, f) = T (a, b, c). Points are centred and scaled per ellipse first for conditioning. The eigenvector is
found element-wise over the batch, from the characteristic cubic (`_constrained_eigenvector`), not by LAPACK's
general eigensolver one 3 x 3 matrix at a time.

Result per ellipse: centre (px), full axis lengths (major, minor) and the angle of the major axis in
degrees from image +x toward image +y (down), in [0, 180). Known answer: points on a circle of radius
r about (x0, y0) give centre (x0, y0) and axes (2r, 2r).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.rays import length

MIN_POINTS = 5
# The scatter matrices S1, S2, S3 as indices into the weighted moments sum(w x^i y^j) of `fit_ellipse`, in the order
# x^4, x^3 y, x^2 y^2, x y^3, y^4, x^3, x^2 y, x y^2, y^3, x^2, x y, y^2, x, y, 1.
_SCATTER = (np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]]), np.array([[5, 6, 9], [6, 7, 10], [7, 8, 11]]),
            np.array([[9, 10, 12], [10, 11, 13], [12, 13, 14]]))
_C1 = np.array([[0.0, 0.0, 2.0], [0.0, -1.0, 0.0], [2.0, 0.0, 0.0]])  # the constraint 4 a c - b^2 as a quadratic form


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
    wsum = np.maximum(w.sum(axis=-1), 1e-300)
    x, y = np.moveaxis(np.nan_to_num(points), -1, 0)
    mean = np.stack([np.einsum("...n,...n->...", w, x), np.einsum("...n,...n->...", w, y)], axis=-1) / wsum[..., None]
    x, y = x - mean[..., 0, None], y - mean[..., 1, None]
    scale = np.sqrt(np.einsum("...n,...n->...", w, x * x + y * y) / wsum)
    scale = np.where(scale > 0, scale, 1.0)
    x, y = x / scale[..., None], y / scale[..., None]
    xx, xy, yy = x * x, x * y, y * y
    monomials = np.stack([xx * xx, xx * xy, xx * yy, xy * yy, yy * yy, xx * x, xx * y, x * yy, yy * y,
                          xx, xy, yy, x, y])
    moments = np.concatenate([np.moveaxis(np.sum(monomials * w, axis=-1), 0, -1), wsum[..., None]], axis=-1)
    s1, s2, s3 = (moments[..., index] for index in _SCATTER)
    with np.errstate(all="ignore"):
        t = -_inverse(s3) @ np.swapaxes(s2, -1, -2)  # non-finite where S3 is singular (collinear points): invalid
        reduced = s1 + s2 @ t
        reduced = np.where(np.isfinite(reduced), (reduced + np.swapaxes(reduced, -1, -2)) / 2, 0.0)
        a1 = _constrained_eigenvector(reduced)
    conic = np.concatenate([a1, (t @ a1[..., None])[..., 0]], axis=-1)
    centre, axes, angle, ok = _conic_to_ellipse(conic)
    centre = centre * scale[..., None] + mean
    valid = enough & ok & (4 * a1[..., 0] * a1[..., 2] - a1[..., 1] ** 2 > 0)
    return Ellipse(centre=centre, axes=axes * scale[..., None], angle_deg=angle, valid=valid)


def _inverse(a: np.ndarray) -> np.ndarray:
    """Inverses of 3 x 3 matrices (..., 3, 3) from the cross products of their rows; inf or nan where singular."""
    rows = np.moveaxis(a, -2, 0)
    columns = np.stack([np.cross(rows[1], rows[2]), np.cross(rows[2], rows[0]), np.cross(rows[0], rows[1])], axis=-1)
    det = np.einsum("...i,...i->...", rows[0], columns[..., 0])
    return columns / det[..., None, None]


def _constrained_eigenvector(r: np.ndarray) -> np.ndarray:
    """The unit eigenvector (..., 3) of M = C1^-1 R for its largest eigenvalue, R (..., 3, 3) symmetric.

    The eigenvalues lam of M solve det(R - lam C1) = 0 with C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]; for R positive
    semi-definite they are real with the signs of C1's eigenvalues (+, -, -) (Fitzgibbon et al. 1999), so the largest
    is the one whose eigenvector has 4 a c - b^2 > 0: the ellipse (0 for points exactly on one). Expanded,
    det(R - lam C1) = -4 lam^3 + 4 (r02 - r11) lam^2 + (r00 r22 - 4 r01 r12 - r02^2 + 4 r11 r02) lam + det R;
    its largest root by the trigonometric formula, polished by two Newton steps, and the eigenvector as the longest
    cross product of two rows of R - lam C1. Element-wise throughout: no per-matrix LAPACK call.
    """
    r00, r01, r02, r11, r12, r22 = r[..., 0, 0], r[..., 0, 1], r[..., 0, 2], r[..., 1, 1], r[..., 1, 2], r[..., 2, 2]
    det = r00 * (r11 * r22 - r12 * r12) - r01 * (r01 * r22 - r12 * r02) + r02 * (r01 * r12 - r11 * r02)
    coef = (-4.0, 4 * (r02 - r11), r00 * r22 - 4 * r01 * r12 - r02 * r02 + 4 * r11 * r02, det)
    a, b, c = (k / -4.0 for k in coef[1:])  # monic: lam^3 + a lam^2 + b lam + c
    p, q = b - a * a / 3, 2 * a**3 / 27 - a * b / 3 + c
    p = np.minimum(p, -1e-300)  # three real roots: p < 0
    arg = np.clip(1.5 * q / p * np.sqrt(-3 / p), -1.0, 1.0)
    lam = 2 * np.sqrt(-p / 3) * np.cos(np.arccos(arg) / 3) - a / 3
    for _ in range(2):
        value = ((coef[0] * lam + coef[1]) * lam + coef[2]) * lam + coef[3]
        slope = (3 * coef[0] * lam + 2 * coef[1]) * lam + coef[2]
        lam = lam - np.where(slope != 0, value / np.where(slope != 0, slope, 1.0), 0.0)
    shifted = r - lam[..., None, None] * _C1
    rows = np.moveaxis(shifted, -2, 0)
    crosses = np.stack([np.cross(rows[0], rows[1]), np.cross(rows[0], rows[2]), np.cross(rows[1], rows[2])], axis=-2)
    lengths = length(crosses)
    best = np.take_along_axis(crosses, np.argmax(lengths, axis=-1)[..., None, None], axis=-2)[..., 0, :]
    return best / np.maximum(np.max(lengths, axis=-1), 1e-300)[..., None]


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
