"""Image features of the simulated subject as a function of the gaze point on the screen.

The forward model (`eyehil.emulator.forward.simulate`) is exact but costs 10-300 ms per call. A device
streaming at up to 2 kHz therefore solves each fixation target exactly once (`FeatureSolver.exact`,
cached per point in a bounded LRU cache of `MAX_CACHED_POINTS`) and interpolates everything that moves
(saccades, pursuits, fixational jitter) bilinearly in a grid of exact solutions over the screen
(`FeatureField`, built once, lazily).

`SolveQueue` runs the exact solves of new fixation targets (and the grid, if it is not built yet) from one
worker thread ("eyehil-solver"), coalesced: while one solve runs, only the latest requested point waits
(older requests are replaced and counted), so a host sending a thousand targets costs at most two solves,
never a queue. The thread hands each solve to a `SolveBackend`: `InThreadSolves` computes it right there
(the solve then holds the GIL, competing with the device's own thread), `solve_process.ProcessSolves` in a
worker process that got the solver once (the device's process only waits on a pipe). The device's thread
never waits for either unless asked to (`Subject`'s `exact_wait_s`): it reads `cached` and
`field_if_ready`, which return at once.

Feature vector per eye (the "channels", image px, OpenCV convention; NaN = not computable):

    0, 1   pupil ellipse centre x, y
    2..4   pupil ellipse second moments m_xx, m_yy, m_xy (px^2): M = R diag((a/2)^2, (b/2)^2) R^T for
           full axes a >= b and angle theta of axis a; moments interpolate smoothly where the angle
           of a near-circular ellipse would jump (`ellipse_from_moments` inverts them)
    5 + 2l, 6 + 2l   glint of LED l, x, y

Blocks are arrays (N points, E tracked eyes in the scene's `sides` order, C channels).
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene

PUPIL_CHANNELS = 5
MAX_CACHED_POINTS = 4096  # exact solutions kept (LRU); each is E x C floats (about 200 bytes)


def ellipse_to_moments(axes: np.ndarray, angle_deg: np.ndarray) -> np.ndarray:
    """Second moments (..., 3) = (m_xx, m_yy, m_xy) px^2 of ellipses with full axes (..., 2) and angle (...)."""
    big, small = (np.asarray(axes, float)[..., 0] / 2) ** 2, (np.asarray(axes, float)[..., 1] / 2) ** 2
    t = np.radians(angle_deg)
    c, s = np.cos(t), np.sin(t)
    return np.stack([big * c**2 + small * s**2, big * s**2 + small * c**2, (big - small) * s * c], axis=-1)


def ellipse_from_moments(moments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full axes (..., 2), a >= b, and angle of axis a in [0, 180) deg, from moments (..., 3)."""
    mxx, myy, mxy = moments[..., 0], moments[..., 1], moments[..., 2]
    half_trace, root = (mxx + myy) / 2, np.hypot((mxx - myy) / 2, mxy)
    big, small = half_trace + root, np.maximum(half_trace - root, 0.0)
    angle = np.degrees(0.5 * np.arctan2(2 * mxy, mxx - myy)) % 180.0
    return np.stack([2 * np.sqrt(big), 2 * np.sqrt(small)], axis=-1), angle


class FeatureSolver:
    """Exact and interpolated features of one subject (one eye anatomy, the scene's sides, a head pose)."""

    def __init__(self, eye: EyeModel, scene: Scene, head: HeadPose | None = None, *,
                 grid_spacing_mm: float = 25.0, grid_margin: float = 0.15, n_pupil_points: int = 30) -> None:
        """`eye`: one anatomy (used as right and left eye); grid for interpolation every `grid_spacing_mm`
        over the screen enlarged by `grid_margin` of its size on each side."""
        self.eye = eye if eye.shape == () else eye[0]
        self.scene, self.head = scene, head or HeadPose()
        self.spacing, self.margin, self.n_points = grid_spacing_mm, grid_margin, n_pupil_points
        self.n_eyes, self.n_leds = len(scene.sides), len(scene.leds)
        self.n_channels = PUPIL_CHANNELS + 2 * self.n_leds
        self._cache: OrderedDict[tuple[float, float], np.ndarray] = OrderedDict()
        self.max_cached = MAX_CACHED_POINTS
        self._lock = threading.Lock()
        self._field: FeatureField | None = None
        self._field_lock = threading.Lock()

    _LOCAL = ("_cache", "_lock", "_field", "_field_lock")  # state that stays in this process

    def __getstate__(self) -> dict:
        """What a worker process needs to solve (anatomy, scene, head, settings): no cache, grid or locks."""
        return {k: v for k, v in self.__dict__.items() if k not in self._LOCAL}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._cache, self._lock = OrderedDict(), threading.Lock()
        self._field, self._field_lock = None, threading.Lock()

    def world(self, xy: np.ndarray) -> np.ndarray:
        """Scene points (N, 3) mm of screen points (N, 2) mm."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        return self.scene.screen.centre + np.column_stack([xy, np.zeros(len(xy))])

    def solve(self, xy: np.ndarray) -> np.ndarray:
        """Exact features (N, E, C) of gaze points (N, 2) screen mm: one forward-model call, no cache."""
        f = simulate(self.eye, self.scene, targets=self.world(xy), head_positions=(self.head,),
                     n_pupil_points=self.n_points)
        ok = f.fixation_valid[0, :, 0] & f.pupil_valid[0, :, 0]  # (S, T)
        pupil = np.concatenate([f.pupil_centre_px[0, :, 0],
                                ellipse_to_moments(f.pupil_axes_px[0, :, 0], f.pupil_angle_deg[0, :, 0])], -1)
        pupil = np.where(ok[..., None], pupil, np.nan)
        glint_ok = f.glint_valid[0, :, 0] & f.fixation_valid[0, :, 0][..., None]  # (S, T, L)
        glints = np.where(glint_ok[..., None], f.glint_px[0, :, 0], np.nan).reshape(*ok.shape, -1)
        return np.concatenate([pupil, glints], axis=-1).transpose(1, 0, 2)

    def exact(self, xy: np.ndarray) -> np.ndarray:
        """Exact features (N, E, C) of gaze points (N, 2), each distinct point solved once and cached."""
        keys = [point_key(p) for p in np.asarray(xy, float).reshape(-1, 2)]
        with self._lock:
            known = {k: self._cache[k] for k in set(keys) if k in self._cache}
        missing = sorted(set(keys) - set(known))
        if missing:
            solved = self.solve(np.array(missing))
            known.update(zip(missing, solved, strict=True))
            self.store(dict(zip(missing, solved, strict=True)))
        return np.stack([known[k] for k in keys]) if keys else np.empty((0, self.n_eyes, self.n_channels))

    def store(self, solved: dict[tuple[float, float], np.ndarray]) -> None:
        """Add exact solutions (E, C) by `point_key` to the cache, evicting the least recently used beyond
        `max_cached`."""
        with self._lock:
            for key, value in solved.items():
                self._cache[key] = value
                self._cache.move_to_end(key)
            while len(self._cache) > self.max_cached:
                self._cache.popitem(last=False)

    def cached(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact features (N, E, C) where cached (NaN elsewhere) and which were (N,) bool; never solves."""
        keys = [point_key(p) for p in np.asarray(xy, float).reshape(-1, 2)]
        out = np.full((len(keys), self.n_eyes, self.n_channels), np.nan)
        found = np.zeros(len(keys), bool)
        with self._lock:
            for i, k in enumerate(keys):
                if k in self._cache:
                    self._cache.move_to_end(k)
                    out[i], found[i] = self._cache[k], True
        return out, found

    @property
    def cache_size(self) -> int:
        """Exact solutions cached now."""
        with self._lock:
            return len(self._cache)

    def has_exact(self, xy: tuple[float, float]) -> bool:
        """True if `exact` at this point is already cached."""
        with self._lock:
            return point_key(xy) in self._cache

    def field_if_ready(self) -> FeatureField | None:
        """The interpolation grid if it is built, else None (never builds it, never waits)."""
        return self._field

    @property
    def field(self) -> FeatureField:
        """The interpolation grid (built on first use, once, by whichever thread comes first)."""
        with self._field_lock:
            if self._field is None:
                self._field = FeatureField.build(self)
            return self._field

    def install_field(self, field: FeatureField) -> None:
        """Use `field` as the interpolation grid unless one is built already (it came from a `SolveBackend`)."""
        with self._field_lock:
            if self._field is None:
                self._field = field

    def interpolate(self, xy: np.ndarray) -> np.ndarray:
        """Interpolated features (N, E, C) of gaze points (N, 2) screen mm."""
        return self.field(np.asarray(xy, float).reshape(-1, 2))


def point_key(xy) -> tuple[float, float]:
    """The cache key of a screen point (mm, rounded to 1 nm)."""
    return round(float(xy[0]), 6), round(float(xy[1]), 6)


class SolveBackend(Protocol):
    """Where `SolveQueue`'s thread has its exact solves computed (module docstring)."""

    def solve(self, xy: np.ndarray) -> np.ndarray:
        """Exact features (N, E, C) of gaze points (N, 2) screen mm, as `FeatureSolver.solve`; blocks until done."""
        ...

    def close(self) -> None:
        """Release what the backend holds; a `solve` under way returns or raises soon after. Idempotent."""
        ...


class InThreadSolves:
    """A `SolveBackend` that solves in the calling thread (`FeatureSolver.solve`, holding the GIL meanwhile)."""

    def __init__(self, solver: FeatureSolver) -> None:
        self.solver = solver

    def solve(self, xy: np.ndarray) -> np.ndarray:
        return self.solver.solve(xy)

    def close(self) -> None:
        """Nothing to release (a solve under way finishes first)."""


class SolveQueue:
    """Exact solves of fixation targets from one worker thread, coalesced; see the module docstring.

    Counters: ``requested``, ``coalesced`` (requests replaced by a newer one before their solve started),
    ``solved``, ``failed`` (a solve raised: logged, the point stays interpolated).
    """

    def __init__(self, solver: FeatureSolver,
                 backend: Callable[[FeatureSolver], SolveBackend] = InThreadSolves) -> None:
        """Start the worker thread, which solves through `backend(solver)` (made here: it must be cheap, e.g.
        start its process on its first solve, which runs on the worker thread); its first job is the grid."""
        self.solver = solver
        self.backend = backend(solver)
        self._cond = threading.Condition()
        self._next: tuple[float, float] | None = None  # the latest point waiting for the worker
        self._running: tuple[float, float] | None = None  # the point being solved now
        self._closing = False
        self.requested = self.coalesced = self.solved = self.failed = 0
        self._thread = threading.Thread(target=self._run, name="eyehil-solver", daemon=True)
        self._thread.start()

    def request(self, xy: tuple[float, float]) -> None:
        """Ask for the exact solution at `xy` (screen mm); returns at once. A request still waiting is replaced."""
        key = point_key(xy)
        with self._cond:
            self.requested += 1
            if key in (self._next, self._running) or self.solver.has_exact(key):
                return
            if self._next is not None:
                self.coalesced += 1
            self._next = key
            self._cond.notify_all()

    @property
    def idle(self) -> bool:
        """True if no point is waiting or being solved."""
        with self._cond:
            return self._next is None and self._running is None

    def busy_with(self, key: tuple[float, float]) -> bool:
        """True if `key` is waiting or being solved."""
        with self._cond:
            return key in (self._next, self._running)

    def wait(self, key: tuple[float, float] | None, timeout_s: float) -> bool:
        """Wait up to `timeout_s` until the grid is built and `key` (if any) is no longer pending; True if so."""
        def done() -> bool:
            return self._closing or (self.solver.field_if_ready() is not None
                                     and (key is None or key not in (self._next, self._running)))
        with self._cond:
            return self._cond.wait_for(done, timeout_s)

    def _run(self) -> None:
        try:  # the grid first: every movement and every unsolved fixation needs it
            if self.solver.field_if_ready() is None:
                self.solver.install_field(FeatureField.build(self.solver, self.backend.solve))
        except Exception:  # a bug in the forward model: logged; the device keeps streaming what it can
            if not self._closing:
                logging.getLogger(__name__).exception("interpolation grid failed")
        with self._cond:
            self._cond.notify_all()
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._closing or self._next is not None)
                if self._closing:
                    return
                self._running, self._next = self._next, None
            try:
                self.solver.store({self._running: self.backend.solve(np.array([self._running]))[0]})
                self.solved += 1
            except Exception:  # as above (or the backend was closed under it)
                if not self._closing:
                    self.failed += 1
                    logging.getLogger(__name__).exception("fixation solve failed at %s", self._running)
            with self._cond:
                self._running = None
                self._cond.notify_all()

    def close(self) -> None:
        """Stop the worker thread and close the backend (a solve under way in this process finishes first; one
        in a worker process is abandoned); idempotent."""
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self.backend.close()
        if self._thread is not threading.current_thread():
            self._thread.join()


class FeatureField:
    """Exact features on a regular grid of screen points, interpolated bilinearly (NaN spreads)."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, values: np.ndarray) -> None:
        """Grid columns `xs` (nx,), rows `ys` (ny,) in screen mm, ascending; `values` (ny, nx, E, C)."""
        self.xs, self.ys, self.values = xs, ys, values

    @classmethod
    def build(cls, solver: FeatureSolver, solve: Callable[[np.ndarray], np.ndarray] | None = None) -> FeatureField:
        """Solve the grid of `solver`'s screen (enlarged by its margin) in one call of `solve` (default
        `solver.solve`: one forward-model call)."""
        half = np.array(solver.scene.screen.size) * (0.5 + solver.margin)
        n = np.maximum(2, np.ceil(2 * half / solver.spacing).astype(int) + 1)
        xs, ys = np.linspace(-half[0], half[0], n[0]), np.linspace(-half[1], half[1], n[1])
        gx, gy = np.meshgrid(xs, ys)
        values = (solve or solver.solve)(np.column_stack([gx.ravel(), gy.ravel()]))
        return cls(xs, ys, values.reshape(len(ys), len(xs), *values.shape[1:]))

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear interpolation (N, E, C) at points (N, 2); points outside the grid are clamped to it."""
        ix, fx = self._locate(self.xs, xy[:, 0])
        iy, fy = self._locate(self.ys, xy[:, 1])
        v = self.values
        fx, fy = fx[:, None, None], fy[:, None, None]
        top = v[iy, ix] * (1 - fx) + v[iy, ix + 1] * fx
        bottom = v[iy + 1, ix] * (1 - fx) + v[iy + 1, ix + 1] * fx
        return top * (1 - fy) + bottom * fy

    @staticmethod
    def _locate(grid: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cell index and fraction of `x` in the ascending `grid`."""
        x = np.clip(x, grid[0], grid[-1])
        i = np.clip(np.searchsorted(grid, x, side="right") - 1, 0, len(grid) - 2)
        return i, (x - grid[i]) / (grid[i + 1] - grid[i])


def tracked_scene(scene: Scene, sides: tuple[str, ...] | None = None) -> Scene:
    """`scene` simulating the eyes `sides` (default: the scene's own), in the order right, left."""
    wanted = tuple(s for s in ("right", "left") if s in (sides or scene.sides))
    return replace(scene, sides=wanted)
