"""The simulated subject: eyes in a head in front of the tracker, looking where a script or the host says.

Positions are screen coordinates of the scene (mm from the screen centre, x toward world +x = the
subject's left, y up; `eyehil.emulator.scene`); times are device microseconds. The subject either plays a
gaze script (`eyehil.emulator.device.gaze`, repeated by default) or follows the host's STIMULUS messages
(`look_at`): after a saccadic latency it makes a main-sequence saccade to the target and fixates it
until told otherwise. `observe(times)` returns the image features at exposure times:

- fixating: the exact forward-model solution for the fixated point (solved once per point, ahead of
  time when a stimulus arrives: `solver.SolveQueue`, coalesced, by default in a worker process:
  `solve_process.ProcessSolves`), plus optional
  fixational jitter (white noise of `jitter_deg` on the gaze direction, applied through the
  interpolation grid's local slope); while the exact solve of a new point is still running, the point is
  interpolated in the grid (counted in `interpolated_holds`);
- moving (saccade, pursuit): interpolated in the solver's grid;
- blinking (scripted, or spontaneous at `blink_rate_hz`): no features.

`observe` never waits for a solve unless `exact_wait_s` > 0 (a device on the fast clock, whose time is
virtual, waits that long at most for the exact solution or the grid); with the default 0 the grid is
built when the subject is (a fixation of a new target is interpolated in it until its exact solve is
done), and samples it could not give (only if it is missing) carry no features, counted in
`unsolved_samples`. A peer's target is range-checked (`look_at`).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.gaze import (
    FOREVER_US,
    Fixation,
    Kind,
    Saccade,
    Segment,
    Timeline,
    clamp_time_us,
    plan,
    position_ok,
)
from eyehil.emulator.device.solve_process import ProcessSolves
from eyehil.emulator.device.solver import FeatureSolver, SolveBackend, SolveQueue, point_key


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

    MAX_PENDING = 64  # requested closures held at once (a page hammering its blink button cannot grow the list)

    def add(self, start_us: int, duration_s: float) -> bool:
        """Close the eyes from `start_us` (device clock, us) for `duration_s` s (0 < duration <= 5 s), besides the
        spontaneous blinks; False (nothing added) if `MAX_PENDING` closures are already pending."""
        if not 0.0 < duration_s <= 5.0:
            raise ValueError(f"blink duration {duration_s} s not in (0, 5]")
        if len(self._intervals) >= self.MAX_PENDING:
            return False
        self._intervals.append((int(start_us), int(start_us) + round(duration_s * 1e6)))
        return True


class Subject:
    """A subject with one eye anatomy (both eyes alike), a head pose and a behaviour; see the module docstring."""

    def __init__(self, solver: FeatureSolver, behaviour: Behaviour | None = None, *,
                 rng: np.random.Generator | None = None, script: list[Segment] | None = None,
                 repeat: bool = True, start: tuple[float, float] = (0.0, 0.0), exact_wait_s: float = 0.0,
                 solves: Callable[[FeatureSolver], SolveBackend] = ProcessSolves) -> None:
        """Follow `script` (repeated if `repeat`) or, without one, fixate `start` until a stimulus comes;
        `exact_wait_s`: how long `observe` may wait for a solve (0: never); `solves`: where the solves of new
        targets run (`solver.SolveBackend`: a worker process by default, `solver.InThreadSolves` in this one)."""
        self.solver = solver
        self.behaviour = behaviour or Behaviour()
        self.rng = rng or np.random.default_rng(0)
        self.timeline = Timeline(start)
        self.blinks = BlinkProcess(self.behaviour.blink_rate_hz, self.behaviour.blink_s, self.rng)
        self.script, self.repeat = script, repeat
        self.exact_wait_s = exact_wait_s
        self.pause_clock: Callable[[], AbstractContextManager] = nullcontext  # the device clock's `paused`, if any
        self.solves = solves
        self._solves: SolveQueue | None = None
        self.targets_refused = 0  # look_at targets ignored (not finite, too far)
        self.interpolated_holds = 0  # fixation samples interpolated because their exact solve was still running
        self.unsolved_samples = 0  # samples without features because the grid was not built yet
        if script:
            self.timeline.cut(0)
            targets = {s.target for s in script if isinstance(s, Fixation)} | {start}
            solver.max_cached = max(solver.max_cached, 2 * len(targets))
            solver.exact(np.array(sorted(targets)))  # every fixation of the script, solved up front
            solver.field  # noqa: B018 - and the grid its movements are interpolated in
        else:
            solver.exact(np.array([start]))  # where the subject looks until the first stimulus
            if exact_wait_s == 0:
                solver.field  # noqa: B018 - never waiting later: the grid must be there before the first stimulus

    def blink(self, start_us: int, duration_s: float) -> bool:
        """Close the eyes at `start_us` (device clock, us) for `duration_s` s; see `BlinkProcess.add`."""
        return self.blinks.add(start_us, duration_s)

    @property
    def screen_centre(self) -> np.ndarray:
        """Screen centre in the scene frame (mm)."""
        return self.solver.scene.screen.centre

    def look_at(self, xy: tuple[float, float], t_us: int) -> int:
        """A target appears at `xy` (screen mm) at `t_us`: plan the saccade; return when the plan changes (us).

        Stops any script. Features before the returned time are unaffected. Never raises on what a peer
        sent: `t_us` is clamped to [0, MAX_TIME_US] (a non-number means now is unknown: 0), and a target that
        is not finite or farther than MAX_POSITION_MM is ignored (counted in `targets_refused`; the plan
        is unchanged and the returned time is FOREVER_US, i.e. nothing to invalidate).
        """
        if not position_ok(xy):
            self.targets_refused += 1
            return FOREVER_US
        try:
            t_us = clamp_time_us(t_us)
        except ValueError:
            self.targets_refused += 1
            return FOREVER_US
        xy = (float(xy[0]), float(xy[1]))
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
        """Ask the worker for the fixation at `xy` unless it is known (coalesced with requests still waiting)."""
        if self.solver.has_exact(xy) and self.solver.field_if_ready() is not None:
            return
        if self._solves is None:
            self._solves = SolveQueue(self.solver, self.solves)
        self._solves.request(xy)

    def _interpolate(self, xy: np.ndarray) -> np.ndarray | None:
        """Interpolated features (N, E, C), or None if the grid is not built yet (waits `exact_wait_s` at most)."""
        if self.solver.field_if_ready() is None:
            if self._solves is None:  # nobody is building it: a subject that never got a stimulus
                self._solves = SolveQueue(self.solver, self.solves)
            if self.exact_wait_s > 0:
                with self.pause_clock():
                    self._solves.wait(None, self.exact_wait_s)
        field = self.solver.field_if_ready()
        return None if field is None else field(np.asarray(xy, float).reshape(-1, 2))

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
            moving = self._interpolate(xy[move])
            if moving is None:
                self.unsolved_samples += int(move.sum())
            else:
                values[move] = moving
        return Observation(values, blink)

    def _fixating(self, xy: np.ndarray) -> np.ndarray:
        """Features at fixated points (N, 2): exact where solved, interpolated while the solve runs; plus jitter."""
        values, found = self.solver.cached(xy)
        if not found.all() and self.exact_wait_s > 0 and self._solves is not None:
            for key in {point_key(p) for p in xy[~found]}:
                if self._solves.busy_with(key):
                    with self.pause_clock():
                        self._solves.wait(key, self.exact_wait_s)
            values, found = self.solver.cached(xy)
        if not found.all():
            if self._solves is None or self._solves.idle:  # never displace a newer target waiting for the worker
                self._prefetch(point_key(xy[~found][0]))  # a point nobody asked for (evicted from the cache)
            approx = self._interpolate(xy[~found])
            if approx is None:
                self.unsolved_samples += int((~found).sum())
            else:
                values[~found] = approx
                self.interpolated_holds += int((~found).sum())
        if self.behaviour.jitter_deg > 0:
            here, moved_xy = self._interpolate(xy), None
            if here is not None:
                distance = float(np.linalg.norm(self.screen_centre))
                sd_mm = distance * np.tan(np.radians(self.behaviour.jitter_deg))
                moved_xy = xy + self.rng.normal(0.0, sd_mm, xy.shape)
                values = values + self._interpolate(moved_xy) - here
        return values

    def close(self) -> None:
        """Stop the solves' worker thread and process (`SolveQueue.close`)."""
        if self._solves is not None:
            self._solves.close()
            self._solves = None
