"""The tracker's online filters: fixations (``FPOG*``) and blinks (``BK*``), one sample at a time.

Fixations: a dispersion filter on the best point of gaze. A fixation continues while each new valid gaze
lies within `radius_deg` (visual angle at the screen's distance) of the fixation's running mean; otherwise
a new fixation starts (``FPOGID`` + 1) at that sample. ``FPOGX/Y`` is the running mean (screen fractions),
``FPOGS`` its start (s, the TIME base), ``FPOGD`` its duration so far (s), ``FPOGV`` 1 while the current
sample's gaze is valid. Invalid samples (blink, no gaze) leave the fixation as it is and report FPOGV 0.

Blinks: ``BKID`` numbers the blink in progress (0 when the eyes are open), ``BKDUR`` is the duration of
the previous blink (s), ``BKPMIN`` the blinks that started in the last 60 s.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

MAX_BLINKS_KEPT = 10_000


@dataclass
class Fixation:
    """The fixation filter's output for one sample."""

    x: float
    y: float
    start_s: float
    duration_s: float
    fid: int
    valid: bool


class FixationFilter:
    """See the module docstring; `radius` in screen fractions per axis (rx, ry)."""

    def __init__(self, radius: tuple[float, float]) -> None:
        self.rx, self.ry = radius
        self._fid = 0
        self._sum = np.zeros(2)
        self._count = 0
        self._start_s = 0.0
        self._last_s = 0.0

    def update(self, t_s: float, xy: np.ndarray, valid: bool) -> Fixation:
        """One sample at TIME `t_s` with best gaze `xy` (fractions)."""
        if valid:
            mean = self._sum / self._count if self._count else None
            if mean is None or ((xy[0] - mean[0]) / self.rx) ** 2 + ((xy[1] - mean[1]) / self.ry) ** 2 > 1.0:
                self._fid += 1
                self._sum, self._count, self._start_s = np.zeros(2), 0, t_s
            self._sum = self._sum + xy
            self._count += 1
            self._last_s = t_s
        mean = self._sum / self._count if self._count else np.zeros(2)
        return Fixation(float(mean[0]), float(mean[1]), self._start_s, max(0.0, self._last_s - self._start_s),
                        self._fid, bool(valid and self._count))


class BlinkCounter:
    """See the module docstring."""

    def __init__(self) -> None:
        self._id = 0
        self._open = True
        self._onset_s = 0.0
        self.last_duration_s = 0.0
        self._onsets: deque[float] = deque(maxlen=MAX_BLINKS_KEPT)

    def update(self, t_s: float, closed: bool) -> tuple[int, float, int]:
        """(BKID, BKDUR, BKPMIN) after a sample at `t_s`."""
        if closed and self._open:
            self._id += 1
            self._open, self._onset_s = False, t_s
            self._onsets.append(t_s)
        elif not closed and not self._open:
            self._open, self.last_duration_s = True, t_s - self._onset_s
        while self._onsets and self._onsets[0] < t_s - 60.0:
            self._onsets.popleft()
        return (0 if self._open else self._id), self.last_duration_s, len(self._onsets)
