"""Frames-only host mode: the device streams camera images, the host finds the features (docs/frames.md).

    with open_tracker(url) as tracker:
        tracker.configure(leds=2, stream=StreamSelect.FRAMES)
        reader = FrameReader(tracker, led_xy_mm=geometry.leds[:, :2])
        tracker.start()
        for sample in reader.samples(count=100):     # eyehil.drivers.wire.Sample, as on the FEATURES path
            ...

`FrameReader` groups the images the wire reassembled (`Wire.images`) by exposure (frame id): one crop
per selected eye (eye RIGHT / LEFT), or one image of the region of interest (eye BOTH). When an
exposure's images are all there it runs `eyehil.drivers.detect` on them (`detect_eye` on a crop or on a region
showing one selected eye, `detect_frame` on a region showing both) and returns a `Sample` with the
exposure's frame id and device time (mid-exposure), the arrival of its last image (host us), and one
`EyeFeatures` per selected eye in the order right, left, each with one glint record per lit LED
(missing ones without VALID): the records a device streams, so `eyehil.drivers.features` and
`eyehil.drivers.calibration` take them unchanged. Coordinates are full-sensor px, as on the wire.

An exposure some of whose images never came is abandoned (`incomplete`) once a later one is complete;
`Sample.skipped_before` counts the exposures missing before a sample (images the device dropped, or
lost on the link). `last_images` holds the images of the last sample (`eyehil stream --frames --save`).
Detection costs about 1 ms per 320 x 240 image: exposures before `detect_from_us` (device time) are not
detected, and their samples carry no eye records, for a caller that discards them anyway (a calibration
while the subject's eyes move to the next target).
LED matching needs the LEDs' world x, y (`led_xy_mm`, from the geometry file); without them LED k makes
the k-th glint from the left of the image. Images are expected as MONO8 (what the emulator sends).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from eyehil.drivers.client import Tracker
from eyehil.drivers.detect import DetectorSettings, detect_eye, detect_frame
from eyehil.drivers.errors import TrackerTimeoutError
from eyehil.drivers.wire import ReceivedImage, Sample
from eyehil.protocols.enums import Eye, EyeSelect, GlintFlags
from eyehil.protocols.header import seq_gap
from eyehil.protocols.native import default_configure
from eyehil.protocols.samples import EyeFeatures, Glint


class FrameReader:
    """Samples detected in streamed images; see the module docstring. Call after CONFIGURE (it reads the eyes
    and LEDs of `tracker.configuration`, or the device's defaults)."""

    def __init__(self, tracker: Tracker, *, led_xy_mm: np.ndarray | None = None,
                 settings: DetectorSettings | None = None) -> None:
        """Read images from `tracker`; `led_xy_mm` (L, 2): the LEDs' world x, y (mm) for matching glints."""
        cfg = tracker.configuration or default_configure(tracker.info)
        self.tracker = tracker
        self.eyes = tuple(e for e in (Eye.RIGHT, Eye.LEFT) if EyeSelect(1 << e) in cfg.eyes)
        self.n_leds = cfg.leds
        self.led_xy_mm = None if led_xy_mm is None else np.asarray(led_xy_mm, float)[: self.n_leds]
        self.settings = settings or DetectorSettings()
        self.incomplete = 0
        self.detect_from_us = 0
        self.last_images: tuple[ReceivedImage, ...] = ()
        self._waiting: dict[int, dict[Eye, ReceivedImage]] = {}
        self._ready: deque[Sample] = deque()
        self._last_frame_id: int | None = None

    def read_sample(self, timeout: float | None = None) -> Sample:
        """The next sample; `TrackerTimeoutError` if none is complete within `timeout` (default the tracker's) s."""
        limit = self.tracker.timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        while True:
            self._collect()
            if self._ready:
                return self._ready.popleft()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TrackerTimeoutError(f"no complete camera image within {limit} s")
            self.tracker.wire.pump(remaining)

    def samples(self, count: int | None = None, timeout: float | None = None) -> Iterator[Sample]:
        """Iterate over samples (`count` of them, or until the caller stops); each waits at most `timeout` s."""
        n = 0
        while count is None or n < count:
            yield self.read_sample(timeout)
            n += 1

    def _collect(self) -> None:
        """Take the wire's images; detect every exposure they complete."""
        images = self.tracker.wire.images
        while images:
            self._add(images.popleft())

    def _add(self, got: ReceivedImage) -> None:
        frame_id, eye = got.image.frame_id, got.image.eye
        group = self._waiting.setdefault(frame_id, {})
        group[eye] = got
        if eye is not Eye.BOTH and not all(e in group for e in self.eyes):
            return
        for older in [f for f in self._waiting if seq_gap(f, frame_id) >= 0]:
            del self._waiting[older]
            self.incomplete += 1
        del self._waiting[frame_id]
        self._ready.append(self._sample(frame_id, group))

    def _sample(self, frame_id: int, group: dict[Eye, ReceivedImage]) -> Sample:
        """The FEATURES-like sample of one exposure's images."""
        skipped = 0 if self._last_frame_id is None else max(0, seq_gap(self._last_frame_id, frame_id))
        self._last_frame_id = frame_id
        last = max(group.values(), key=lambda g: g.host_us)
        self.last_images = tuple(group.values())
        detect = last.device_us >= self.detect_from_us
        eyes = tuple(padded(record, self.n_leds) for record in self._detect(group)) if detect else ()
        return Sample(last.seq, frame_id, last.device_us, last.host_us, eyes, skipped_before=skipped)

    def _detect(self, group: dict[Eye, ReceivedImage]) -> tuple[EyeFeatures, ...]:
        """One record per selected eye, right then left."""
        kw = {"led_xy_mm": self.led_xy_mm, "settings": self.settings}
        whole = group.get(Eye.BOTH)
        if whole is None:
            return tuple(detect_eye(group[e].image.pixels, self.n_leds, roi_xy=_origin(group[e]), eye=e, **kw).features
                         for e in self.eyes)
        if len(self.eyes) == 2:
            features, _ = detect_frame(whole.image.pixels, 2, self.n_leds, roi_xy=_origin(whole), **kw)
            return features.eyes
        return (detect_eye(whole.image.pixels, self.n_leds, roi_xy=_origin(whole), eye=self.eyes[0], **kw).features,)


def _origin(got: ReceivedImage) -> tuple[int, int]:
    return got.image.roi_x, got.image.roi_y


def padded(record: EyeFeatures, n_leds: int) -> EyeFeatures:
    """`record` with one glint record per LED 0 .. n_leds - 1, in LED order (missing ones without VALID)."""
    by_led = {g.led: g for g in record.glints}
    glints = tuple(by_led.get(led, Glint(led, 0.0, 0.0, GlintFlags(0))) for led in range(n_leds))
    return replace(record, glints=glints)


def reader_for(tracker: Tracker, frames: bool, led_xy_mm: np.ndarray | None = None) -> Tracker | FrameReader:
    """What to read samples from: the tracker itself (FEATURES) or, with `frames`, a `FrameReader` over it."""
    return FrameReader(tracker, led_xy_mm=led_xy_mm) if frames else tracker
