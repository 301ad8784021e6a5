"""A batched two-unknown Newton iteration with a forward-difference Jacobian.

Every solver of the forward model (glint point, pupil exit point, fixation pose) is a small 2 x 2
non-linear system per element of a large batch; one vectorised Newton over the whole batch beats a
generic optimiser per element. The residual function maps q (..., 2) to (r (..., 2), ok (...)); the
Jacobian is (r(q + h e_j) - r(q)) / h, each step is capped at `max_step` (a damped Newton), and an
element stops moving once its step is below `tol`.

With `subset=True` the residual also takes the batch index of the elements to evaluate,
f(q (K, 2), index) -> (r (K, 2), ok (K,)) with `index` a tuple of index arrays into the batch shape (or
None for the whole batch); once fewer than `SUBSET_FRACTION` of the elements still move, only those are
evaluated. Each element's arithmetic is the same either way (the residuals are element-wise), so the
solution is bit for bit that of the full-batch iteration; in the forward model's pupil solve the last
iteration moves a few in 10,000 points, and skipping the rest saves a fifth of the residual evaluations.

`secant2d` solves the same systems by Broyden's method: the Jacobian is updated from each step instead of
re-differenced, so an iteration costs one residual evaluation instead of three. The pupil solve uses it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.rays import length

Residual = Callable[..., tuple[np.ndarray, np.ndarray]]
SUBSET_FRACTION = 0.5


@dataclass(frozen=True)
class NewtonResult:
    """Solution q (..., 2), its residual r (..., 2), ok (...) and the iterations used."""

    q: np.ndarray
    residual: np.ndarray
    ok: np.ndarray
    iterations: int


def newton2d(
    f: Residual,
    q0: np.ndarray,
    *,
    h: float = 1e-7,
    tol: float = 1e-11,
    max_iter: int = 40,
    max_step: float = 1.0,
    subset: bool = False,
) -> NewtonResult:
    """Solve f(q) = 0 for q (..., 2) from q0, element by element (see the module docstring)."""
    q = np.array(q0, dtype=float, copy=True)
    moving = np.ones(q.shape[:-1], dtype=bool)
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 - reported below
        if subset and np.count_nonzero(moving) < SUBSET_FRACTION * moving.size:
            index = np.nonzero(moving)
            q_sub, moving_sub = _step(lambda x, i=index: f(x, i), q[index], np.ones(len(index[0]), dtype=bool),
                                      h, tol, max_step)
            q[index], moving[index] = q_sub, moving_sub
        else:
            q, moving = _step((lambda x: f(x, None)) if subset else f, q, moving, h, tol, max_step)
        if not moving.any():
            break
    r, ok = f(q, None) if subset else f(q)
    return NewtonResult(q=q, residual=r, ok=ok & np.all(np.isfinite(r), axis=-1), iterations=iterations)


def _step(
    f: Residual, q: np.ndarray, moving: np.ndarray, h: float, tol: float, max_step: float
) -> tuple[np.ndarray, np.ndarray]:
    """One damped Newton step of the elements that still move: (new q, still moving)."""
    r, ok = f(q)
    rx, okx = f(q + np.array([h, 0.0]))
    ry, oky = f(q + np.array([0.0, h]))
    j00, j10 = (rx[..., 0] - r[..., 0]) / h, (rx[..., 1] - r[..., 1]) / h
    j01, j11 = (ry[..., 0] - r[..., 0]) / h, (ry[..., 1] - r[..., 1]) / h
    det = j00 * j11 - j01 * j10
    good = ok & okx & oky & np.isfinite(det) & (det != 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        dq = -np.stack([j11 * r[..., 0] - j01 * r[..., 1], -j10 * r[..., 0] + j00 * r[..., 1]], axis=-1)
        dq /= det[..., None]
    size = length(dq)
    dq *= np.minimum(1.0, max_step / np.where(size > 0, size, 1.0))[..., None]
    step = moving & good
    q = np.where(step[..., None], q + np.nan_to_num(dq), q)
    moving &= good & (size > tol)
    return q, moving


def secant2d(
    f: Residual,
    q0: np.ndarray,
    *,
    jacobian: np.ndarray | None = None,
    h: float = 1e-7,
    tol: float = 1e-11,
    max_iter: int = 40,
    max_step: float = 1.0,
    subset: bool = True,
) -> NewtonResult:
    """Solve f(q) = 0 for q (..., 2) from q0 by Broyden's method, element by element.

    `f(q, index)` follows the subset convention of `newton2d(subset=True)`; with `subset=False` it is f(q) and
    always evaluates the whole batch. The Jacobian starts as
    `jacobian` (..., 2, 2), dr/dq at q0 (broadcast to the batch; elements where it is not finite, or all
    when it is None, start from a forward difference of step `h`) and is then updated from each step's
    change of residual (the rank-one "good" Broyden update, C. G. Broyden, Math. Comp. 19:577-593, 1965):
    one residual evaluation per iteration instead of newton2d's three, at superlinear rather than quadratic
    convergence. A step that does not lower |r| refreshes that element's Jacobian by forward differences.
    Steps are capped at `max_step`; an element stops once its next step would be below `tol`, keeping the
    point whose residual was evaluated (so `residual` is exactly f at `q`, with no final evaluation). Once
    fewer than `SUBSET_FRACTION` of the elements still move, only those are evaluated."""
    if not subset:
        whole = f
        f = lambda q, index: whole(q)  # noqa: E731 - the same residual, called with the whole batch only
    q = np.array(q0, dtype=float, copy=True)
    batch = q.shape[:-1]
    r, ok = f(q, None)
    r, ok = np.array(np.broadcast_to(r, (*batch, 2))), np.array(np.broadcast_to(ok, batch))
    if jacobian is None:
        j = np.full((*batch, 2, 2), np.nan)
    else:
        j = np.array(np.broadcast_to(np.asarray(jacobian, dtype=float), (*batch, 2, 2)))
    cold = ~np.isfinite(j[..., 0, 0] + j[..., 0, 1] + j[..., 1, 0] + j[..., 1, 1])
    if cold.any():
        index = None if cold.all() or not subset else np.nonzero(cold)
        start = (q, r) if index is None else (q[index], r[index])
        fresh = difference_jacobian(f, *start, index, h)
        j[cold] = fresh.reshape(-1, 2, 2) if index is not None else fresh[cold]
    state = [r[..., 0], r[..., 1], j[..., 0, 0], j[..., 0, 1], j[..., 1, 0], j[..., 1, 1]]  # r0 r1 a b c d
    moving = np.ones(batch, dtype=bool)
    iterations = 0
    for iterations in range(1, max_iter + 1):  # noqa: B007 - reported below
        count = np.count_nonzero(moving)
        if count == 0:
            break
        index = None if not subset or count >= SUBSET_FRACTION * moving.size else np.nonzero(moving)
        if index is None:
            qs, oks, live = q, ok, moving & ok
            r0, r1, a, b, c, d = state
        else:
            qs, oks = q[index], ok[index]
            live = oks
            r0, r1, a, b, c, d = (v[index] for v in state)
        det = a * d - b * c
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            dx, dy = (b * r1 - d * r0) / det, (c * r0 - a * r1) / det  # -J^-1 r
            size = np.sqrt(dx * dx + dy * dy)
        go = live & np.isfinite(size) & (size > tol)
        scale = np.where(go, np.minimum(1.0, max_step / np.where(go, size, 1.0)), 0.0)
        dx, dy = np.where(go, dx, 0.0) * scale, np.where(go, dy, 0.0) * scale
        if index is None:
            moving &= go
        else:
            moving[index] = go
        if not go.any():
            break
        qn = qs + np.stack([dx, dy], axis=-1)
        rn, okn = f(qn, index)
        n0, n1 = rn[..., 0], rn[..., 1]
        norm2 = np.where(go, dx * dx + dy * dy, 1.0)
        e0, e1 = (n0 - r0 - (a * dx + b * dy)) / norm2, (n1 - r1 - (c * dx + d * dy)) / norm2
        a, b, c, d = a + e0 * dx, b + e0 * dy, c + e1 * dx, d + e1 * dy
        n0, n1, okn = np.where(go, n0, r0), np.where(go, n1, r1), np.where(go, okn, oks)
        worse = go & okn & (n0 * n0 + n1 * n1 >= r0 * r0 + r1 * r1)
        if worse.any():
            if subset:
                sub = np.nonzero(worse) if index is None else tuple(i[worse] for i in index)
                fresh = difference_jacobian(f, qn[worse], np.stack([n0[worse], n1[worse]], axis=-1), sub, h)
            else:
                fresh = difference_jacobian(f, qn, np.stack([n0, n1], axis=-1), None, h)[worse]
            for v, k in zip((a, b, c, d), ((0, 0), (0, 1), (1, 0), (1, 1)), strict=True):
                v[worse] = fresh[:, k[0], k[1]]
        if index is None:
            q, ok = qn, okn
            state = [n0, n1, a, b, c, d]
        else:
            q[index], ok[index] = qn, okn
            for v, new in zip(state, (n0, n1, a, b, c, d), strict=True):
                v[index] = new
    r = np.stack(state[:2], axis=-1)
    return NewtonResult(q=q, residual=r, ok=ok & np.all(np.isfinite(r), axis=-1), iterations=iterations)


def difference_jacobian(f: Residual, q: np.ndarray, r: np.ndarray, index, h: float) -> np.ndarray:
    """Forward-difference dr/dq (..., 2, 2) at q (r = f(q)); NaN where a neighbouring evaluation is not ok."""
    rx, okx = f(q + np.array([h, 0.0]), index)
    ry, oky = f(q + np.array([0.0, h]), index)
    j = np.stack([(rx - r) / h, (ry - r) / h], axis=-1)
    j[~(okx & oky)] = np.nan
    return j
