"""Image features of the simulated subject as a function of the gaze point on the screen.

The forward model (`eyehil.emulator.forward.simulate`) is exact but costs about 10 ms per call. A device
streaming at up to 2 kHz therefore solves each fixation target exactly once (`FeatureSolver.exact`,
cached per point) and interpolates everything that moves (saccades, pursuits, fixational jitter)
bilinearly in a grid of exact solutions over the screen (`FeatureField`, built once, lazily).

Feature vector per eye (the "channels", image px, OpenCV convention; NaN = not computable):

    0, 1   pupil ellipse centre x, y
    2..4   pupil ellipse second moments m_xx, m_yy, m_xy (px^2): M = R diag((a/2)^2, (b/2)^2) R^T for
           full axes a >= b and angle theta of axis a; moments interpolate smoothly where the angle
           of a near-circular ellipse would jump (`ellipse_from_moments` inverts them)
    5 + 2l, 6 + 2l   glint of LED l, x, y

Blocks are arrays (N points, E tracked eyes in the scene's `sides` order, C channels).
"""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene

PUPIL_CHANNELS = 5


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
        self._cache: dict[tuple[float, float], np.ndarray] = {}
        self._lock = threading.Lock()
        self._field: FeatureField | None = None
        self._field_lock = threading.Lock()

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
        keys = [(round(float(x), 6), round(float(y), 6)) for x, y in np.asarray(xy, float).reshape(-1, 2)]
        with self._lock:
            missing = sorted({k for k in keys if k not in self._cache})
        if missing:
            solved = self.solve(np.array(missing))
            with self._lock:
                self._cache.update(zip(missing, solved, strict=True))
        with self._lock:
            return np.stack([self._cache[k] for k in keys]) if keys else np.empty((0, self.n_eyes, self.n_channels))

    def has_exact(self, xy: tuple[float, float]) -> bool:
        """True if `exact` at this point is already cached."""
        with self._lock:
            return (round(float(xy[0]), 6), round(float(xy[1]), 6)) in self._cache

    @property
    def field(self) -> FeatureField:
        """The interpolation grid (built on first use, once, by whichever thread comes first)."""
        with self._field_lock:
            if self._field is None:
                self._field = FeatureField.build(self)
            return self._field

    def interpolate(self, xy: np.ndarray) -> np.ndarray:
        """Interpolated features (N, E, C) of gaze points (N, 2) screen mm."""
        return self.field(np.asarray(xy, float).reshape(-1, 2))


class FeatureField:
    """Exact features on a regular grid of screen points, interpolated bilinearly (NaN spreads)."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, values: np.ndarray) -> None:
        """Grid columns `xs` (nx,), rows `ys` (ny,) in screen mm, ascending; `values` (ny, nx, E, C)."""
        self.xs, self.ys, self.values = xs, ys, values

    @classmethod
    def build(cls, solver: FeatureSolver) -> FeatureField:
        """Solve the grid of `solver`'s screen (enlarged by its margin) in one forward-model call."""
        half = np.array(solver.scene.screen.size) * (0.5 + solver.margin)
        n = np.maximum(2, np.ceil(2 * half / solver.spacing).astype(int) + 1)
        xs, ys = np.linspace(-half[0], half[0], n[0]), np.linspace(-half[1], half[1], n[1])
        gx, gy = np.meshgrid(xs, ys)
        values = solver.solve(np.column_stack([gx.ravel(), gy.ravel()]))
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
