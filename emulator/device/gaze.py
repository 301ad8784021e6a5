"""The simulated subject's gaze over time: a script of fixations, saccades, pursuits and blinks.

Positions are SCREEN coordinates of the scene (`eyehil.emulator.scene.Screen.to_screen`): mm in the screen
plane from its centre, x toward world +x (the subject's left), y up. Times are device microseconds.

A script is a sequence of segments, each starting where the previous one ended:

- `Fixation(target, duration_s)`: a saccade to `target` if the gaze is elsewhere, then a hold;
- `Saccade(target, duration_s=None)`: a minimum-jerk movement, s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5,
  lasting by default the main sequence D = 21 ms + 2.2 ms/deg x amplitude (Carpenter 1988);
- `Pursuit(target, speed_deg_s)`: constant angular speed along the straight line on the screen;
- `Blink(duration_s)`: the lids close; the gaze holds.

`plan` turns segments into `Piece`s with absolute times; `Timeline` holds the pieces, evaluates them
at many times at once (vectorised) and can be redirected (a STIMULUS from the host).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

FOREVER_US = 1 << 62
MAIN_SEQUENCE_MS = (21.0, 2.2)  # intercept (ms) and slope (ms/deg) of saccade duration


class Kind(IntEnum):
    """What the eye does during a piece."""

    HOLD = 0  # fixating a point: features are exact there (plus optional fixational jitter)
    MOVE = 1  # saccade or pursuit: features interpolated
    BLINK = 2  # eyes closed


@dataclass(frozen=True)
class Fixation:
    """Look at `target` (screen mm) for `duration_s` (after a saccade there if needed)."""

    target: tuple[float, float]
    duration_s: float


@dataclass(frozen=True)
class Saccade:
    """Jump to `target` (screen mm); `duration_s` None = main sequence."""

    target: tuple[float, float]
    duration_s: float | None = None


@dataclass(frozen=True)
class Pursuit:
    """Follow a target moving in a straight line to `target` (screen mm) at `speed_deg_s`."""

    target: tuple[float, float]
    speed_deg_s: float = 10.0


@dataclass(frozen=True)
class Blink:
    """Close the eyes for `duration_s`."""

    duration_s: float = 0.15


Segment = Fixation | Saccade | Pursuit | Blink


@dataclass(frozen=True)
class Piece:
    """One stretch of the timeline, [start_us, end_us): the gaze goes from `a` to `b` (screen mm)."""

    start_us: int
    end_us: int
    kind: Kind
    a: tuple[float, float]
    b: tuple[float, float]
    smooth: bool = True  # minimum-jerk profile (saccade) instead of linear (pursuit)


def visual_angle_deg(screen_centre: np.ndarray, a, b) -> float:
    """Angle (deg) between screen points `a` and `b` seen from the head-frame origin (the cyclopean eye)."""
    pa, pb = (np.asarray(screen_centre, float) + np.array([p[0], p[1], 0.0]) for p in (a, b))
    cos = pa @ pb / (np.linalg.norm(pa) * np.linalg.norm(pb))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def saccade_duration_s(amplitude_deg: float) -> float:
    """Main-sequence duration of a saccade of `amplitude_deg`."""
    intercept, slope = MAIN_SEQUENCE_MS
    return (intercept + slope * amplitude_deg) / 1e3


def _move(t_us: int, a, b, duration_s: float, smooth: bool) -> Piece:
    """A movement piece from `a` to `b` starting at `t_us`."""
    return Piece(t_us, t_us + max(1, round(duration_s * 1e6)), Kind.MOVE, tuple(a), tuple(b), smooth)


def plan(segments: list[Segment], start: tuple[float, float], t0_us: int, screen_centre: np.ndarray) -> list[Piece]:
    """Absolute pieces for `segments` starting at `t0_us` with the gaze at `start`."""
    pieces: list[Piece] = []
    t, here = t0_us, tuple(start)
    for seg in segments:
        target = tuple(getattr(seg, "target", here))
        if isinstance(seg, Blink):
            new = [Piece(t, t + round(seg.duration_s * 1e6), Kind.BLINK, here, here)]
        elif isinstance(seg, Pursuit):
            amplitude = visual_angle_deg(screen_centre, here, target)
            new = [_move(t, here, target, amplitude / seg.speed_deg_s, smooth=False)]
        else:
            amplitude = visual_angle_deg(screen_centre, here, target)
            new = [_move(t, here, target, saccade_duration_s(amplitude), True)] if target != here else []
            if isinstance(seg, Saccade) and seg.duration_s is not None and new:
                new = [_move(t, here, target, seg.duration_s, True)]
            if isinstance(seg, Fixation):
                start_hold = new[-1].end_us if new else t
                new.append(Piece(start_hold, start_hold + round(seg.duration_s * 1e6), Kind.HOLD, target, target))
        pieces += new
        t, here = (new[-1].end_us, new[-1].b) if new else (t, here)
    return pieces


class Timeline:
    """Pieces in start order; the latest piece started at time t describes the gaze at t.

    New pieces are appended at `cursor_us` (the end of the plan so far, or the time of the last `cut`).
    A piece that has ended with nothing after it holds its end point.
    """

    def __init__(self, start: tuple[float, float] = (0.0, 0.0)) -> None:
        """Start holding `start` (screen mm) from time 0, forever."""
        self.pieces: list[Piece] = [Piece(0, FOREVER_US, Kind.HOLD, tuple(start), tuple(start))]
        self.cursor_us = FOREVER_US

    def position(self, t_us: int) -> tuple[float, float]:
        """Gaze position (screen mm) at `t_us`."""
        xy = self.evaluate(np.array([t_us]))[0][0]
        return float(xy[0]), float(xy[1])

    def cut(self, t_us: int) -> tuple[float, float]:
        """Forget the plan from `t_us` on (a movement under way keeps its timing up to then); return the
        position at `t_us`, where the next `extend` starts."""
        here = self.position(t_us)
        self.pieces = [p for p in self.pieces if p.start_us < t_us] or [Piece(0, t_us, Kind.HOLD, here, here)]
        self.cursor_us = t_us
        return here

    def extend(self, pieces: list[Piece]) -> None:
        """Append pieces planned from `cursor_us`; the cursor moves to the end of the last one."""
        if pieces:
            self.pieces += pieces
            self.cursor_us = pieces[-1].end_us

    def hold_forever(self, at: tuple[float, float]) -> None:
        """Hold `at` from the cursor on."""
        self.extend([Piece(self.cursor_us, FOREVER_US, Kind.HOLD, tuple(at), tuple(at))])

    def drop_before(self, t_us: int) -> None:
        """Forget pieces that ended before `t_us` (keeps the list short in long runs)."""
        later = [i for i, p in enumerate(self.pieces) if p.start_us <= t_us]
        first = later[-1] if later else 0
        self.pieces = self.pieces[first:]

    def evaluate(self, times_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gaze (N, 2) screen mm and `Kind` (N,) at `times_us` (N,).

        A time past its piece's end (nothing planned after it) holds the piece's end point.
        """
        t = np.asarray(times_us, dtype=np.int64)
        p = self.pieces
        starts = np.array([q.start_us for q in p], dtype=np.int64)
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(p) - 1)
        a, b = np.array([q.a for q in p])[idx], np.array([q.b for q in p])[idx]
        start, end = starts[idx], np.array([q.end_us for q in p], dtype=np.int64)[idx]
        kind, smooth = np.array([q.kind for q in p])[idx], np.array([q.smooth for q in p])[idx]
        tau = np.clip((t - start) / np.maximum(end - start, 1), 0.0, 1.0)
        s = np.where(smooth, tau**3 * (10 - 15 * tau + 6 * tau**2), tau)
        xy = a + s[:, None] * (b - a)
        return xy, np.where(t >= end, Kind.HOLD, kind)
