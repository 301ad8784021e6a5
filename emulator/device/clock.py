"""The device's clock: microseconds since power-up, in real time or as fast as the link allows.

A virtual tracker timestamps everything with one clock (docs/protocol.md section 4: u64 us of the
sender's monotonic clock since an arbitrary epoch, here the clock's creation). Two kinds:

- `RealTimeClock(speed=1.0)`: ``time.monotonic_ns`` since creation, optionally scaled (``speed=10``
  runs the device ten times faster than the wall clock: a 500 Hz stream then carries 5000 samples per
  wall-clock second, with device timestamps 2 ms apart).
- `FastClock()`: "as fast as possible". The streamer `push`es device time to the next sample's exposure
  time whenever the link has room, so samples are produced as fast as the host consumes them (the link's
  buffers are the only pacing). A native device (`build.build_device`: loop://, pty, TCP, USB/IP) runs it in
  lockstep with its host (``wall_floor=False``): device time moves only with those pushes, so a slow or
  descheduled host (a busy machine) never makes samples fall due faster than it reads them, and nothing is
  dropped for it. Servers that never push (the ZeroMQ and Open Gaze facades) keep the wall-clock floor:
  their device time never runs slower than the wall clock.

`ManualClock` (tests, benchmarks) moves only when told. All are monotonic and thread-safe for one
writer (the streamer) and any number of readers.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol


class Clock(Protocol):
    """What a device core needs from a clock."""

    fast: bool  # True if the streamer may push time ahead of the wall clock

    def now_us(self) -> int:
        """Device time (us since the clock's epoch); never decreases."""
        ...

    def push(self, t_us: int) -> None:
        """Advance device time to at least `t_us` (fast clocks only; others ignore it)."""
        ...

    def wall_delay_s(self, t_us: int) -> float:
        """Wall-clock seconds until device time reaches `t_us` (0 if it already has)."""
        ...


class RealTimeClock:
    """Wall-clock time since creation, multiplied by `speed` (> 0)."""

    fast = False

    def __init__(self, speed: float = 1.0) -> None:
        """Start the clock at 0 us now."""
        if not speed > 0:
            raise ValueError(f"clock speed must be > 0, got {speed}")
        self.speed = float(speed)
        self._t0_ns = time.monotonic_ns()

    def now_us(self) -> int:
        """Scaled microseconds since creation."""
        return int((time.monotonic_ns() - self._t0_ns) * self.speed) // 1000

    def push(self, t_us: int) -> None:
        """Real time cannot be pushed: ignored."""

    def wall_delay_s(self, t_us: int) -> float:
        """Seconds of wall clock until device time `t_us`."""
        return max(0.0, (t_us - self.now_us()) / 1e6 / self.speed)


class FastClock:
    """Device time = max(wall-clock time since creation minus the time spent `paused`, the latest `push`);
    without `wall_floor`, the latest `push` alone (lockstep: virtual time moves only when the streamer says).

    `paused()` is a context manager for the device's own waits (the subject waiting for an exact fixation
    solve): virtual time does not run on while the simulation itself is behind, so no sample falls due
    (and is dropped) only because the emulator was computing.
    """

    fast = True

    def __init__(self, wall_floor: bool = True) -> None:
        """Start the clock at 0 us now; `wall_floor`: device time never runs slower than the wall clock."""
        self.wall_floor = wall_floor
        self._t0_ns = time.monotonic_ns()
        self._pushed = 0
        self._lock = threading.Lock()
        self._paused_since: int | None = None

    @contextmanager
    def paused(self) -> Iterator[None]:
        """Stop the wall-clock floor for the duration (device time still moves with `push`)."""
        with self._lock:
            nested = self._paused_since is not None
            if not nested:
                self._paused_since = time.monotonic_ns()
        try:
            yield
        finally:
            if not nested:
                with self._lock:
                    self._t0_ns += time.monotonic_ns() - self._paused_since
                    self._paused_since = None

    def now_us(self) -> int:
        """Microseconds since creation (less the time paused), or the pushed time if that is later (without the
        wall floor: the pushed time)."""
        if not self.wall_floor:
            with self._lock:
                return self._pushed
        with self._lock:
            wall_ns = self._paused_since if self._paused_since is not None else time.monotonic_ns()
        wall = (wall_ns - self._t0_ns) // 1000
        with self._lock:
            self._pushed = max(self._pushed, wall)
            return self._pushed

    def push(self, t_us: int) -> None:
        """Jump device time forward to `t_us` (never backward)."""
        with self._lock:
            self._pushed = max(self._pushed, int(t_us))

    def wall_delay_s(self, t_us: int) -> float:
        """In lockstep, 0 (a pushing streamer never waits); with the wall floor, the wall-clock seconds until device
        time reaches `t_us` if nobody pushes (a server that does not push waits as on the real clock)."""
        if not self.wall_floor:
            return 0.0
        return max(0.0, (t_us - self.now_us()) / 1e6)


class ManualClock:
    """Device time that moves only when told (`advance`, `push`): tests and benchmarks on simulated time."""

    fast = False

    def __init__(self, start_us: int = 0) -> None:
        """Start at `start_us`."""
        self._now = int(start_us)
        self._lock = threading.Lock()

    def now_us(self) -> int:
        """The current simulated time."""
        with self._lock:
            return self._now

    def advance(self, dt_us: int) -> int:
        """Move time forward by `dt_us` (>= 0); return the new time."""
        with self._lock:
            self._now += max(0, int(dt_us))
            return self._now

    def push(self, t_us: int) -> None:
        """Move time forward to `t_us` (never backward)."""
        with self._lock:
            self._now = max(self._now, int(t_us))

    def wall_delay_s(self, t_us: int) -> float:
        """Simulated time does not pass by itself: no wall-clock wait."""
        return 0.0


def make_clock(kind: str = "real", speed: float = 1.0, lockstep: bool = False) -> Clock:
    """`"real"` (optionally scaled by `speed`) or `"fast"` (with `lockstep`, without the wall-clock floor: for a
    streamer that pushes time as its host reads)."""
    if kind == "real":
        return RealTimeClock(speed)
    if kind == "fast":
        return FastClock(wall_floor=not lockstep)
    raise ValueError(f"clock must be 'real' or 'fast', got {kind!r}")
