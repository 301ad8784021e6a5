"""The virtual camera: exposures at the configured rate, and what its feature detector reports.

Exposure k of a stream started at device time t0 (us) has its mid-exposure time
t_k = t0 + round((k + 1) * 1e6 / rate) and frame id (first + k) mod 2^32, where `first` counts every
exposure since power-up (docs/protocol.md section 5.3). Features for upcoming exposures are prepared in
blocks of about 20 ms (one `Subject.observe` call each); `invalidate(t)` forgets prepared exposures
from t on when the subject's plan changes.

Detection (`detect`), per selected eye (right, left) and enabled LED, in full-sensor pixels: a pupil is
DETECTED if its features exist, the eye is open and its centre lies in the region (the region of
interest, or the sensor); PARTIAL if its bounding box leaves the sensor, CLIPPED if it leaves the region
of interest; BLINK while the eyes are closed. A glint is VALID if it exists, the eye is open and it lies
in the region. Fields their flags declare meaningless are sent as 0.0 (never NaN).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from eyehil.emulator.device.solver import PUPIL_CHANNELS, ellipse_from_moments
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.batch import FeaturesBatch
from eyehil.protocols.enums import Eye, GlintFlags, PupilFlags

PREPARE_S = 0.05  # features are prepared this far ahead (device seconds)
FAST_PREPARE_S = 0.25  # the same on a fast clock, whose time waits for the subject's solves (fewer, larger blocks)
FAST_PREPARE_MIN = 100  # and at least this many exposures: a block costs about 1 ms besides its exposures (at 100 Hz
# a quarter second of them cost 27 us an image, 100 of them 9)


@dataclass(frozen=True)
class Selection:
    """What a stream reports: eyes (Eye values, right before left), the first `leds` LEDs, a region."""

    eyes: tuple[Eye, ...]
    leds: int
    roi: tuple[int, int, int, int] | None = None  # x, y, w, h px; None = the full sensor


@dataclass(frozen=True)
class Exposures:
    """Consecutive exposures: detected features, mid-exposure times (N,) us, and what the subject showed the
    camera: its channels (N, E', C) for the tracked eyes (`Subject.observe`; what frames are drawn from) and
    whether its eyes were closed (N,)."""

    batch: FeaturesBatch
    time_us: np.ndarray
    values: np.ndarray
    blink: np.ndarray

    def __len__(self) -> int:
        return len(self.time_us)

    def __getitem__(self, s: slice) -> Exposures:
        """The exposures in slice `s` (the eye ids are shared)."""
        b = self.batch
        batch = FeaturesBatch(eye=b.eye, **{name: getattr(b, name)[s] for name in _PER_SAMPLE})
        return Exposures(batch, self.time_us[s], self.values[s], self.blink[s])


_PER_SAMPLE = tuple(f.name for f in fields(FeaturesBatch) if f.name != "eye")  # FeaturesBatch's arrays over samples


def _inside(xy: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray:
    """True where pixel coordinates (..., 2) lie on the pixels of region (x, y, w, h)."""
    x, y, w, h = region
    return (xy[..., 0] >= x - 0.5) & (xy[..., 0] < x + w - 0.5) & (xy[..., 1] >= y - 0.5) & (xy[..., 1] < y + h - 0.5)


def _box_inside(centre: np.ndarray, half: np.ndarray, region: tuple[int, int, int, int]) -> np.ndarray:
    """True where the boxes centre +- half (..., 2) lie wholly in region (x, y, w, h)."""
    return _inside(centre - half, region) & _inside(centre + half, region)


def detect(values: np.ndarray, blink: np.ndarray, sel: Selection, tracked: tuple[Eye, ...],
           sensor: tuple[int, int]) -> dict[str, np.ndarray]:
    """FEATURES fields (arrays over N samples, E selected eyes, G glints) from observed channels (N, E', C)."""
    full = (0, 0, *sensor)
    region = sel.roi or full
    n = len(values)
    cols = [tracked.index(e) if e in tracked else None for e in sel.eyes]
    v = np.stack([values[:, c] if c is not None else np.full(values.shape[::2], np.nan) for c in cols], axis=1)
    centre, moments = v[..., 0:2], v[..., 2:PUPIL_CHANNELS]
    glints = v[..., PUPIL_CHANNELS:PUPIL_CHANNELS + 2 * sel.leds].reshape(n, len(cols), sel.leds, 2)
    open_eye = ~blink[:, None]
    axes, angle = ellipse_from_moments(np.nan_to_num(moments))
    half = np.sqrt(np.maximum(np.nan_to_num(moments[..., :2]), 0.0))
    found = np.isfinite(v[..., :PUPIL_CHANNELS]).all(-1) & open_eye & _inside(np.nan_to_num(centre), region)
    flags = np.where(found, PupilFlags.DETECTED, 0)
    flags |= np.where(found & ~_box_inside(centre, half, full), PupilFlags.PARTIAL, 0)
    flags |= np.where(found & (sel.roi is not None) & ~_box_inside(centre, half, region), PupilFlags.CLIPPED, 0)
    flags |= np.where(blink[:, None], PupilFlags.BLINK, 0)
    glint_ok = np.isfinite(glints).all(-1) & open_eye[..., None] & _inside(np.nan_to_num(glints), region)
    return {
        "flags": flags.astype(np.uint8),
        "centre": np.where(found[..., None], centre, 0.0), "axes": np.where(found[..., None], axes, 0.0),
        "angle_deg": np.where(found, angle, 0.0), "confidence": found.astype(float),
        "glint_xy": np.where(glint_ok[..., None], glints, 0.0),
        "glint_flags": np.where(glint_ok, GlintFlags.VALID, 0).astype(np.uint8),
    }


class Camera:
    """Exposure schedule, frame ids and prepared features of one subject; see the module docstring."""

    def __init__(self, subject: Subject, sensor: tuple[int, int], tracked: tuple[Eye, ...]) -> None:
        """`tracked`: the eyes the subject simulates, in the order of its feature arrays."""
        self.subject, self.sensor, self.tracked = subject, sensor, tracked
        self.frames_since_power_up = 0
        self._t0 = self._k = 0
        self._rate = 1
        self._sel = Selection(tracked, 1)
        self._ready: Exposures | None = None  # prepared exposures, of which the first `_pos` are taken
        self._pos = 0
        self.prepare_s = PREPARE_S  # how far ahead exposures are prepared (device seconds)
        self.prepare_min = 1  # and at least this many exposures

    def start(self, t0_us: int, rate_hz: int, selection: Selection) -> None:
        """Begin exposing at `rate_hz` after `t0_us`."""
        self._t0, self._rate, self._sel, self._k, self._ready, self._pos = t0_us, rate_hz, selection, 0, None, 0

    def stop(self) -> None:
        """End the stream; prepared exposures are forgotten."""
        self._ready, self._pos = None, 0

    def time_of(self, k: int) -> int:
        """Mid-exposure time (us) of exposure `k` of this stream."""
        return self._t0 + round((k + 1) * 1e6 / self._rate)

    @property
    def taken(self) -> int:
        """Exposures of this stream taken or skipped so far (the next one is `time_of(taken)`)."""
        return self._k

    def due(self, now_us: int) -> int:
        """Exposures whose mid-time is at or before `now_us` and not yet taken."""
        k_now = int((now_us - self._t0) * self._rate // 1_000_000) - 1  # last k with time_of(k) <= now (approx.)
        while self.time_of(k_now + 1) <= now_us:
            k_now += 1
        while k_now >= self._k and self.time_of(k_now) > now_us:
            k_now -= 1
        return max(0, k_now + 1 - self._k)

    def take(self, count: int) -> Exposures:
        """The next `count` exposures, detected."""
        while self._left < count:
            self._prepare(count - self._left)
        out = self._ready[self._pos:self._pos + count]
        self._pos += count
        self._advance(count)
        return out

    @property
    def prepared_until_us(self) -> int:
        """Mid-exposure time (us) of the last exposure prepared (what the subject does until then is fixed); any
        thread may read it."""
        ready = self._ready
        return int(ready.time_us[-1]) if ready is not None and len(ready) else self.time_of(self._k - 1)

    @property
    def _left(self) -> int:
        """Prepared exposures not yet taken."""
        return 0 if self._ready is None else len(self._ready) - self._pos

    def skip(self, count: int) -> None:
        """Drop the next `count` exposures (a link too slow): they keep their frame ids, unsent."""
        if count >= self._left:
            self._ready, self._pos = None, 0
        else:
            self._pos += count
        self._advance(count)

    def invalidate(self, from_us: int) -> None:
        """Forget prepared exposures at or after `from_us`."""
        if self._ready is not None:
            keep = self._pos + int(np.searchsorted(self._ready.time_us[self._pos:], from_us))
            self._ready, self._pos = self._ready[self._pos:keep], 0

    def _advance(self, count: int) -> None:
        self._k += count
        self.frames_since_power_up += count

    def _prepare(self, at_least: int) -> None:
        """Observe and detect the next block of exposures after those already prepared (at least `at_least`,
        `prepare_min` and `prepare_s` of them: each block costs about as much as one exposure)."""
        have = self._left
        count = max(at_least, self.prepare_min, round(self._rate * self.prepare_s))
        k = np.arange(self._k + have, self._k + have + count)
        times = self._t0 + np.round((k + 1) * 1e6 / self._rate).astype(np.int64)
        obs = self.subject.observe(times)
        fields_ = detect(obs.values, obs.blink, self._sel, self.tracked, self.sensor)
        first = self.frames_since_power_up + have
        batch = FeaturesBatch(
            frame_id=((first + np.arange(count)) % (1 << 32)).astype(np.uint32), eye=np.array(self._sel.eyes),
            glint_led=np.broadcast_to(np.arange(self._sel.leds), (count, len(self._sel.eyes), self._sel.leds)),
            **fields_)
        new = Exposures(batch, times, obs.values, obs.blink)
        self._ready = new if not have else _concat(self._ready[self._pos:], new)
        self._pos = 0


def _concat(a: Exposures, b: Exposures) -> Exposures:
    """Exposures a then b (same eyes)."""
    joined = {name: np.concatenate([getattr(a.batch, name), getattr(b.batch, name)]) for name in _PER_SAMPLE}
    return Exposures(FeaturesBatch(eye=a.batch.eye, **joined), *(np.concatenate([getattr(a, k), getattr(b, k)])
                                                    for k in ("time_us", "values", "blink")))
