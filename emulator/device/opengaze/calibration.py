"""The calibration the tracker paces (``CALIBRATE_START``), on device time.

Points are Open Gaze screen fractions (origin top-left, y down; `samples.screen_fraction`). Point k
(0-based; ``PT`` = k + 1 on the wire) starts at ``t0 + k (delay + timeout)``: ``CALIB_START_PT`` is sent
and the simulated subject looks there (after its saccadic latency and a saccade); at
``t0 + (k + 1)(delay + timeout)`` ``CALIB_RESULT_PT`` follows. The exposures of point k taken in
[start + settle, its end] are averaged per eye into one fixation (`zmq_calibration.Session`), with
``settle = max(delay, MIN_SETTLE_S)``: the subject's latency and saccade (about 0.25 s) come first. After
the last point the gazer (`zmq_calibration.fit`, Guestrin or Blignaut as the device options say) is fitted
on a worker thread; ``CALIB_RESULT`` then carries per point the target and each eye's gaze estimate for
that point's fixation (``LX, LY, LV, RX, RY, RV``), from which the per-point errors follow;
``CALIBRATE_RESULT_SUMMARY`` reports their mean error in screen pixels and the count of valid points.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.opengaze.samples import SIDES, fraction_to_screen, screen_fraction
from eyehil.emulator.device.pupil.calibration import Fixations, Gazer, Session, fit
from eyehil.emulator.scene import Scene

MIN_SETTLE_S = 0.35
#: Gazepoint's default 9-point pattern (fractions, top-left origin), row by row.
DEFAULT_POINTS = tuple((x, y) for y in (0.1, 0.5, 0.9) for x in (0.1, 0.5, 0.9))
MAX_POINTS = 49


@dataclass(frozen=True)
class PointResult:
    """One calibration point: target (x, y) fractions and each eye's estimate (L, R) (2, 2), validity (2,)."""

    target: tuple[float, float]
    gaze: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class Outcome:
    """A finished calibration: the gazer (None if the fit failed, with `reason`) and its per-point results."""

    gazer: Gazer | None
    points: tuple[PointResult, ...]
    reason: str = ""

    def summary(self, screen_px: tuple[int, int]) -> tuple[float, int]:
        """(AVE_ERROR px, VALID_POINTS): mean distance of valid eye estimates from their targets in screen
        pixels of `screen_px` (w, h), and the points with at least one valid eye."""
        errors = [np.hypot(*((p.gaze[e] - p.target) * screen_px)) for p in self.points for e in range(2)
                  if p.valid[e]]
        return (float(np.mean(errors)) if errors else 0.0), sum(bool(p.valid.any()) for p in self.points)


def _evaluate(fixations: Fixations, scene: Scene, eye_ids: tuple[int, ...], method: str) -> Outcome:
    """Fit, then map each point's own fixation (runs on the worker thread)."""
    gazer = fit(fixations, scene, eye_ids, method)
    targets = screen_fraction(scene.screen.size, fixations.targets_mm)
    if isinstance(gazer, str):
        return Outcome(None, tuple(PointResult(tuple(t), np.zeros((2, 2)), np.zeros(2, bool)) for t in targets),
                       gazer)
    mm, used = gazer.map_eyes(fixations.pupil, fixations.glints[:, :, :gazer.leds], fixations.valid)
    frac = screen_fraction(scene.screen.size, mm)
    sides = [("right", "left")[e] for e in eye_ids]
    points = []
    for k, t in enumerate(targets):
        gaze, valid = np.zeros((2, 2)), np.zeros(2, bool)
        for i, side in enumerate(SIDES):
            if side in sides:
                c = sides.index(side)
                valid[i] = bool(used[k, c])
                gaze[i] = frac[k, c] if valid[i] else 0.0
        points.append(PointResult((float(t[0]), float(t[1])), gaze, valid))
    return Outcome(gazer, tuple(points))


class CalibrationRun:
    """One run of the tracker-paced calibration; see the module docstring. Not thread-safe (the device's)."""

    def __init__(self, scene: Scene, eye_ids: tuple[int, ...], points: list[tuple[float, float]], t0_us: int,
                 delay_s: float, timeout_s: float, method: str) -> None:
        self.scene, self.eye_ids, self.method = scene, eye_ids, method
        self.points = list(points)
        self.t0_us, self.step_us = t0_us, round((delay_s + timeout_s) * 1e6)
        self.session = Session(max(delay_s, MIN_SETTLE_S))
        self._next = 0  # events handed out: 2k = start of point k, 2k + 1 = its result
        self._fit: Future | None = None
        self.done = False  # the outcome was handed out
        self._executor: ThreadPoolExecutor | None = None

    def screen_mm(self, k: int) -> tuple[float, float]:
        """Scene screen mm of point k."""
        x, y = fraction_to_screen(self.scene.screen.size, np.array(self.points[k]))
        return float(x), float(y)

    def events(self, now_us: int) -> list[tuple[str, int, int]]:
        """("start" | "result", k, device time us) of the events due by `now_us`, each once; after the last
        result the fit starts."""
        out = []
        while self._next < 2 * len(self.points):
            k, is_result = divmod(self._next, 2)
            t_us = self.t0_us + (k + is_result) * self.step_us
            if t_us > now_us:
                break
            s = t_us / 1e6
            self.session.add_ref(self.screen_mm(k), s)  # a start opens the target, its result ends it
            out.append(("result" if is_result else "start", k, t_us))
            self._next += 1
        if self._next == 2 * len(self.points) and self._fit is None and not self.done:
            self._start_fit(self.t0_us + len(self.points) * self.step_us)
        return out

    def _start_fit(self, stop_us: int) -> None:
        fixations = self.session.fixations(stop_us / 1e6)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eyehil-opengaze-fit")
        self._fit = self._executor.submit(_evaluate, fixations, self.scene, self.eye_ids, self.method)

    @property
    def collecting(self) -> bool:
        """True while points are still shown (exposures go to the session)."""
        return self._next < 2 * len(self.points)

    def outcome(self) -> Outcome | None:
        """The outcome once the fit has finished (then the worker is stopped), else None."""
        if self._fit is None or not self._fit.done():
            return None
        future, self._fit, self.done = self._fit, None, True
        self.close()
        try:
            return future.result()
        except Exception as exc:  # a numerical failure of the fit is a failed calibration, not a dead device
            return Outcome(None, (), f"the fit failed: {exc!r}")

    def close(self) -> None:
        """Stop the worker (an unfinished fit is abandoned)."""
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
