"""The simulated subject: eyes in a head in front of the tracker, looking where a script or the host says.

Positions are screen coordinates of the scene (mm from the screen centre, x toward world +x = the
subject's left, y up; `eyehil.emulator.scene`); times are device microseconds. The subject either plays a
gaze script (`eyehil.emulator.device.gaze`, repeated by default) or follows the host's STIMULUS messages
(`look_at`): after a saccadic latency it makes a main-sequence saccade to the target and fixates it
until told otherwise. `observe(times)` returns the image features at exposure times:

- fixating: the exact forward-model solution for the fixated point (solved once per point, ahead of
  time on a worker thread when a stimulus arrives), plus optional fixational jitter (white noise of
  `jitter_deg` on the gaze direction, applied through the interpolation grid's local slope);
- moving (saccade, pursuit): interpolated in the solver's grid;
- blinking (scripted, or spontaneous at `blink_rate_hz`): no features.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.gaze import Fixation, Kind, Saccade, Segment, Timeline, plan
from eyehil.emulator.device.solver import FeatureSolver


@dataclass(frozen=True)
class Behaviour:
    """How the subject reacts and how still it keeps its eyes (seconds, degrees, Hz)."""

    latency_s: float = 0.2  # saccadic latency after a target appears
    latency_sd_s: float = 0.0  # its trial-to-trial SD (needs an rng)
    jitter_deg: float = 0.0  # fixational jitter, SD of the gaze direction per sample
    blink_rate_hz: float = 0.0  # spontaneous blinks per second (Poisson)
    blink_s: float = 0.15  # duration of a spontaneous blink


@dataclass(frozen=True)
class Observation:
    """Features (N, E, C) (see `eyehil.emulator.device.solver`; NaN = not found) and eyes closed (N,)."""

    values: np.ndarray
    blink: np.ndarray


class BlinkProcess:
    """Spontaneous blinks: a Poisson process of closures of fixed duration, generated lazily."""

    def __init__(self, rate_hz: float, duration_s: float, rng: np.random.Generator) -> None:
        """No blinks if `rate_hz` is 0."""
        self.rate_hz, self.duration_us, self.rng = rate_hz, round(duration_s * 1e6), rng
        self._intervals: list[tuple[int, int]] = []
        self._next_us = self._gap()

    def _gap(self) -> int:
        """Microseconds to the next blink onset."""
        return round(self.rng.exponential(1e6 / self.rate_hz)) if self.rate_hz > 0 else 1 << 62

    def mask(self, times_us: np.ndarray) -> np.ndarray:
        """True where a spontaneous blink covers the time (times ascending)."""
        end = int(times_us[-1]) if len(times_us) else 0
        while self._next_us <= end:
            self._intervals.append((self._next_us, self._next_us + self.duration_us))
            self._next_us += self.duration_us + self._gap()
        self._intervals = [iv for iv in self._intervals if iv[1] > int(times_us[0])] if len(times_us) else []
        closed = np.zeros(len(times_us), bool)
        for start, stop in self._intervals:
            closed |= (times_us >= start) & (times_us < stop)
        return closed


class Subject:
    """A subject with one eye anatomy (both eyes alike), a head pose and a behaviour; see the module docstring."""

    def __init__(self, solver: FeatureSolver, behaviour: Behaviour | None = None, *,
                 rng: np.random.Generator | None = None, script: list[Segment] | None = None,
                 repeat: bool = True, start: tuple[float, float] = (0.0, 0.0)) -> None:
        """Follow `script` (repeated if `repeat`) or, without one, fixate `start` until a stimulus comes."""
        self.solver = solver
        self.behaviour = behaviour or Behaviour()
        self.rng = rng or np.random.default_rng(0)
        self.timeline = Timeline(start)
        self.blinks = BlinkProcess(self.behaviour.blink_rate_hz, self.behaviour.blink_s, self.rng)
        self.script, self.repeat = script, repeat
        self._executor: ThreadPoolExecutor | None = None
        self._pending: dict[tuple[float, float], Future] = {}
        if script:
            self.timeline.cut(0)
            targets = {s.target for s in script if isinstance(s, Fixation)} | {start}
            solver.exact(np.array(sorted(targets)))  # every fixation of the script, solved up front
            solver.field  # noqa: B018 - and the grid its movements are interpolated in

    @property
    def screen_centre(self) -> np.ndarray:
        """Screen centre in the scene frame (mm)."""
        return self.solver.scene.screen.centre

    def look_at(self, xy: tuple[float, float], t_us: int) -> int:
        """A target appears at `xy` (screen mm) at `t_us`: plan the saccade; return when the plan changes (us).

        Stops any script. Features before the returned time are unaffected.
        """
        self.script = None
        latency = self.behaviour.latency_s + self.behaviour.latency_sd_s * self.rng.standard_normal()
        effect_us = t_us + max(0, round(latency * 1e6))
        here = self.timeline.cut(effect_us)
        if tuple(xy) != here:
            self.timeline.extend(plan([Saccade(tuple(xy))], here, effect_us, self.screen_centre))
        self.timeline.hold_forever(tuple(xy))
        self._prefetch(tuple(xy))
        return effect_us

    def _prefetch(self, xy: tuple[float, float]) -> None:
        """Solve the fixation at `xy` on the worker thread unless it is known or under way."""
        key = (round(xy[0], 6), round(xy[1], 6))
        if self.solver.has_exact(key) or key in self._pending:
            return
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eyehil-solver")
            self._executor.submit(lambda: self.solver.field)  # the grid for the saccades, built once
        self._pending[key] = self._executor.submit(self.solver.exact, np.array([key]))

    def _extend_script(self, t_us: int) -> None:
        """Append script cycles until the plan covers `t_us`."""
        while self.script and self.timeline.cursor_us <= t_us:
            here = self.timeline.position(self.timeline.cursor_us)
            self.timeline.extend(plan(self.script, here, self.timeline.cursor_us, self.screen_centre))
            if not self.repeat:
                self.script = None
                self.timeline.hold_forever(self.timeline.position(self.timeline.cursor_us))

    def observe(self, times_us: np.ndarray) -> Observation:
        """Features at exposure times (N,) us, ascending."""
        times = np.asarray(times_us, dtype=np.int64)
        if len(times) == 0:
            return Observation(np.empty((0, self.solver.n_eyes, self.solver.n_channels)), np.zeros(0, bool))
        self._extend_script(int(times[-1]))
        self.timeline.drop_before(int(times[0]))
        xy, kind = self.timeline.evaluate(times)
        blink = (kind == Kind.BLINK) | self.blinks.mask(times)
        values = np.full((len(times), self.solver.n_eyes, self.solver.n_channels), np.nan)
        hold, move = (kind == Kind.HOLD) & ~blink, (kind == Kind.MOVE) & ~blink
        if hold.any():
            values[hold] = self._fixating(xy[hold])
        if move.any():
            values[move] = self.solver.interpolate(xy[move])
        return Observation(values, blink)

    def _fixating(self, xy: np.ndarray) -> np.ndarray:
        """Exact features at fixated points (N, 2), plus jitter."""
        for key in {(round(x, 6), round(y, 6)) for x, y in xy.tolist()} & set(self._pending):
            self._pending.pop(key).result()
        values = self.solver.exact(xy)
        if self.behaviour.jitter_deg > 0:
            distance = float(np.linalg.norm(self.screen_centre))
            sd_mm = distance * np.tan(np.radians(self.behaviour.jitter_deg))
            moved = xy + self.rng.normal(0.0, sd_mm, xy.shape)
            values = values + self.solver.interpolate(moved) - self.solver.interpolate(xy)
        return values

    def close(self) -> None:
        """Stop the worker thread (pending solves are cancelled)."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        self._pending.clear()
