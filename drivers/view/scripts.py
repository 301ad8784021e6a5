"""Host-side gaze scripts: where the view shows the target over time (sent to the emulator as STIMULUS).

Positions are STIMULUS coordinates: mm from the screen's top-left corner as the subject sees it, x right,
y down (`eyehil.drivers.calibration.screen_to_stimulus` converts from geometry screen mm). Times are seconds
since the script started (host clock). Pure functions of time; the session sends a new STIMULUS when
`target_at` changes (fixations, grid) or every `step_s` (pursuit).

- ``fixations``: a fixed pseudo-random sequence of points over the central 80 % of the screen, `dwell_s` each;
- ``pursuit``: a Lissajous path (x at 1/period, y at 2/period) over the central 70 %, in steps of `step_s`;
- ``grid``: a 3 x 3 grid over the central 80 %, row by row, `dwell_s` each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NAMES = ("fixations", "pursuit", "grid")


@dataclass(frozen=True)
class GazeScript:
    """A target path on a screen of `size_mm` (width, height); see the module docstring."""

    name: str
    size_mm: tuple[float, float]
    dwell_s: float = 1.5
    period_s: float = 12.0
    step_s: float = 0.25  # pursuit: the target moves in steps of this many seconds (each is a new fixation the
    # emulator solves exactly, about 0.1 s of CPU: smaller steps make it fall behind)
    seed: int = 1

    def __post_init__(self) -> None:
        if self.name not in NAMES:
            raise ValueError(f"gaze script must be one of {NAMES}, got {self.name!r}")
        if not (self.dwell_s > 0 and self.period_s > 0 and self.step_s > 0):
            raise ValueError("dwell_s, period_s and step_s must be positive")

    def points(self) -> np.ndarray:
        """The fixation points (K, 2) of ``fixations`` and ``grid`` (empty for ``pursuit``)."""
        w, h = self.size_mm
        if self.name == "grid":
            fx, fy = np.meshgrid([0.1, 0.5, 0.9], [0.1, 0.5, 0.9])
            return np.stack([fx.ravel() * w, fy.ravel() * h], axis=1)
        if self.name == "fixations":
            rng = np.random.default_rng(self.seed)
            return rng.uniform([0.1 * w, 0.1 * h], [0.9 * w, 0.9 * h], size=(12, 2))
        return np.empty((0, 2))

    def target_at(self, t_s: float) -> tuple[float, float]:
        """The target (x, y) mm at `t_s` seconds after the start."""
        w, h = self.size_mm
        if self.name == "pursuit":
            t = math.floor(max(t_s, 0.0) / self.step_s) * self.step_s
            phase = 2 * math.pi * t / self.period_s
            return (w / 2 + 0.35 * w * math.sin(phase), h / 2 + 0.35 * h * math.sin(2 * phase))
        points = self.points()
        x, y = points[int(max(t_s, 0.0) // self.dwell_s) % len(points)]
        return float(x), float(y)
