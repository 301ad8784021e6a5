"""What the page is shown of a stream: the rows of the confidence chart, the last record of each eye, the records
drawn over the images of the same exposure, gaze, and the health figures. No I/O: the session feeds it and
publishes what it returns.

Image coordinates are full-sensor px (OpenCV convention); gaze and targets STIMULUS mm (top-left origin, x right,
y down); chart rows are [device time s, confidence right, confidence left, gaze x, gaze y] (None where absent).
Every collection is bounded (`MAX_RECORDS`, `MAX_PENDING`).
"""

from __future__ import annotations

import numpy as np

from eyehil.drivers.calibration import Result, screen_to_stimulus
from eyehil.drivers.client import ClockSync
from eyehil.drivers.features import binocular_samples, eye_samples
from eyehil.drivers.gaze.geometry import Screen
from eyehil.drivers.view.payload import confidence_of, eye_record, image_message, number, xy
from eyehil.drivers.view.stats import StreamStats
from eyehil.drivers.wire import HostStats, ReceivedImage, Sample, host_now_us
from eyehil.protocols.enums import Eye

MAX_TICK_SAMPLES = 1_000  # chart rows per tick (beyond: every k-th)
MAX_PENDING = 4 * MAX_TICK_SAMPLES  # chart rows kept between ticks
MAX_RECORDS = 256  # recent eye records kept to draw over the images of the same exposure
HOST_COUNTERS = ("lost_frames", "crc_errors", "samples_overflowed", "images_incomplete", "images_overflowed", "images")


def estimate_gaze(samples: list[Sample], result: Result | None, screen: Screen | None) -> np.ndarray:
    """Gaze (N, 2) STIMULUS mm of `samples` with a calibration `result` (NaN without one or where unusable)."""
    if result is None or screen is None:
        return np.full((len(samples), 2), np.nan)
    try:
        batch = eye_samples(samples, Eye.RIGHT) if result.method == "guestrin" else binocular_samples(samples)
        gaze = result.calibration.estimate(batch)
    except ValueError:  # the stream's LEDs or eyes no longer fit the calibration
        return np.full((len(samples), 2), np.nan)
    return screen_to_stimulus(screen, gaze)


def _remember(table: dict, key: tuple[int, int], value: dict) -> None:
    table[key] = value
    while len(table) > MAX_RECORDS:
        del table[next(iter(table))]


class LiveStream:
    """See the module docstring; `max_image_hz` limits the images shown per eye."""

    def __init__(self, max_image_hz: float = 120.0) -> None:
        self.image_s = 1 / max_image_hz
        self.stats = StreamStats()
        self.images_skipped = 0
        self.reset()

    def reset(self) -> None:
        """A new stream: forget the rows, records and figures."""
        self.pending: list[list] = []
        self.last: dict[str, dict] = {}  # eye name -> its last record
        self.records: dict[tuple[int, int], dict] = {}  # (frame id, eye) -> record: the overlay of its image
        self.truths: dict[tuple[int, int], dict] = {}  # (frame id, eye) -> the device's record ("detect" mode)
        self.gaze: np.ndarray | None = None
        self._last_image: dict[int, float] = {}  # eye -> device time (s) of the last image shown
        self.stats.reset()

    def add(self, samples: list[Sample], gaze: np.ndarray, sync: ClockSync | None) -> None:
        """Received samples and their gaze (N, 2): latency, rate, chart rows, records."""
        for sample, g in zip(samples, gaze, strict=True):
            latency = None if sync is None else (sample.host_us - sync.to_host_us(sample.device_us)) / 1e3
            self.stats.add(sample.host_us, latency)
            right, left = sample.eye(Eye.RIGHT), sample.eye(Eye.LEFT)
            self.pending.append([round(sample.device_us / 1e6, 4), confidence_of(right), confidence_of(left),
                                 *(xy(g) or [None, None])])
            for record in (right, left):
                if record is not None:
                    encoded = {**eye_record(record), "frame_id": sample.frame_id}
                    self.last[encoded["eye"]] = encoded
                    _remember(self.records, (sample.frame_id, int(record.eye)), encoded)
        if len(gaze) and np.isfinite(gaze[-1]).all():
            self.gaze = gaze[-1]
        if len(self.pending) > MAX_PENDING:
            del self.pending[: len(self.pending) - MAX_PENDING]

    def add_truth(self, samples: list[Sample]) -> None:
        """The device's own FEATURES while the host detects: drawn as the reference (on the emulator, the ground
        truth of the rendered images)."""
        for sample in samples:
            for record in sample.eyes:
                _remember(self.truths, (sample.frame_id, int(record.eye)),
                          {**eye_record(record), "frame_id": sample.frame_id})

    def image(self, got: ReceivedImage) -> tuple[bytes, dict | None] | None:
        """The image message of `got` with the records of its exposure, and its record; None if this eye's last
        image shown was exposed less than 1 / max_image_hz before it, in device time (counted in
        `images_skipped`). Device time, not arrival: images that arrive together (a link or a loop that delivers
        in bursts) are all shown, and only a device faster than max_image_hz is thinned."""
        image, eye = got.image, int(got.image.eye)
        t = got.device_us / 1e6
        last = self._last_image.get(eye)
        if last is not None and 0.0 <= t - last < self.image_s:  # earlier than the last: a new stream
            self.images_skipped += 1
            return None
        self._last_image[eye] = t
        record = self.records.get((image.frame_id, eye))
        message = image_message(image.eye, image.frame_id, (image.roi_x, image.roi_y), image.pixels, got.device_us,
                                record, self.truths.get((image.frame_id, eye)))
        return message, record

    def tick(self, host: HostStats | None, counters: dict, target: tuple[float, float] | None) -> dict:
        """The "tick" message: the rows since the last tick, the last records, gaze, target and health."""
        rows, self.pending = self.pending, []
        if len(rows) > MAX_TICK_SAMPLES:
            rows = rows[:: -(-len(rows) // MAX_TICK_SAMPLES)]
        p50, p99 = self.stats.latency_ms()
        stats = {"rate_hz": round(self.stats.rate_hz(host_now_us()), 1),
                 "latency_p50_ms": None if p50 is None else number(p50, 2),
                 "latency_p99_ms": None if p99 is None else number(p99, 2),
                 "images_skipped": self.images_skipped, **counters}
        if host is not None:
            stats |= {k: getattr(host, k) for k in HOST_COUNTERS}
        return {"type": "tick", "samples": rows, "eyes": dict(self.last), "gaze": xy(self.gaze), "target": xy(target),
                "stats": stats}
