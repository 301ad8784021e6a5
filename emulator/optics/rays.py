"""Refraction and reflection of rays at a surface (vector forms), batched over (..., 3).

Snell's law in vector form (Glassner 1989; gkaModelEye `refractRay`): for a unit direction d meeting a
surface with unit normal n (flipped so that n . d < 0), eta = n1 / n2, cos_i = -n . d,
k = 1 - eta^2 (1 - cos_i^2); the refracted direction is eta d + (eta cos_i - sqrt(k)) n, and k < 0 is
total internal reflection (invalid). Reflection: d' = d - 2 (d . n) n.

Known answer: d = (sin 30deg, 0, -cos 30deg), n = (0, 0, 1), n1 = 1, n2 = 1.5 gives
sin(theta_t) = sin 30deg / 1.5 = 1/3.
"""

from __future__ import annotations

import numpy as np


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def affine(m: np.ndarray, o: np.ndarray, p: np.ndarray) -> np.ndarray:
    """m p + o for points p (..., N, 3), matrices m (..., 3, 3) and offsets o (..., 3), one row of m at a time
    (several times faster than einsum or matmul over many small 3 x 3 products)."""
    x, y, z = (p[..., k] for k in range(3))
    m, o = m[..., None, :, :], o[..., None, :]
    out = np.empty(np.broadcast_shapes(p.shape, o.shape))
    for j in range(3):
        out[..., j] = x * m[..., j, 0] + y * m[..., j, 1] + z * m[..., j, 2] + o[..., j]
    return out


def length(v: np.ndarray) -> np.ndarray:
    """|v| along the last axis: `np.linalg.norm(v, axis=-1)` bit for bit (the squares added in order), without its
    slow reduction over a short axis."""
    total = v[..., 0] * v[..., 0]
    for k in range(1, v.shape[-1]):
        total = total + v[..., k] * v[..., k]
    return np.sqrt(total)


def unit(v: np.ndarray) -> np.ndarray:
    """v / |v| along the last axis."""
    return v / length(v)[..., None]


def refract(
    d: np.ndarray, n: np.ndarray, n1: np.ndarray | float, n2: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Refracted unit direction from medium index n1 into n2, and validity (False on total internal
    reflection). Either orientation of the normal `n` is accepted."""
    cos_i = -_dot(n, d)
    n = np.where((cos_i < 0)[..., None], -n, n)
    cos_i = np.abs(cos_i)
    eta = np.asarray(n1, dtype=float) / np.asarray(n2, dtype=float)
    k = 1.0 - eta**2 * (1.0 - cos_i**2)
    valid = k >= 0
    t = eta[..., None] * d + (eta * cos_i - np.sqrt(np.maximum(k, 0.0)))[..., None] * n
    return t, valid


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror reflection of direction d at a surface with unit normal n (either orientation)."""
    return d - 2.0 * _dot(d, n)[..., None] * n


def distance_to_line(point: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Distance (mm) of `point` from the line origin + s * direction (direction unit)."""
    v = point - origin
    return length(v - _dot(v, direction)[..., None] * direction)
