"""The device's image stream: which exposures become FRAME_CHUNKs, and when their chunks go out.

Images (docs/protocol.md sections 5.3 and 7, FRAME_CHUNK), rendered by `frames` from the exposure's
observation (`camera.Exposures.values`) with the noise `frames.exposure_noise(seed, frame_id, eye)`:

- no region of interest (the full-sensor code): one crop per selected eye (eye RIGHT / LEFT) of
  `FrameOptions.crop_px` (320 x 240, clipped to the sensor), centred on that eye's pupil and kept on the
  sensor; during a blink the crop stays where it was and shows the eye with its lids shut;
- a region of interest: the region as a whole (eye BOTH), showing the selected eyes.

Capacity: images never delay FEATURES. The core holds the chunks of at most one exposure and numbers and
encodes them only when `release` lets them out, which keeps the bytes downstream (the link's backlog at
the last poll, what was released since, and the core's queued output) under `budget_bytes`; FEATURES and
responses queue ahead of every chunk not yet released (the protocol lets a device send FEATURES between
the chunks of an image). Dropped, each counted per image in STATUS `frames_dropped`: the images of an
exposure due while the previous exposure's chunks still wait, those of all but the newest exposure taken
at one poll (the device renders at most one exposure per poll, so rendering never makes it fall behind
its clock), those of exposures skipped for the FEATURES limit, and those abandoned by STOP. `sent`
(`frames_sent`) counts images whose last chunk was released.

Rendering ahead (`FrameOptions.workers` > 0): images are rendered by a `render_pool.RenderPool` of that many
processes while the link carries the previous ones. At most `FrameOptions.ahead` exposures are in flight
(rendering, rendered, or with chunks waiting); the newest exposures of a poll take the free places and the
others' images are dropped and counted, as are images whose rendering failed. Chunks still leave in exposure
order and under the same budget. With ``workers=0`` the device renders on its own thread, one exposure in flight.
`room` tells a fast clock whether it may take another exposure (`VirtualTracker.fast_room`).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, wait
from dataclasses import dataclass, field

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver, closed
from eyehil.emulator.device.camera import Exposures, Selection
from eyehil.emulator.device.frames import ExposureRenderer
from eyehil.emulator.device.render_pool import RenderJob, RenderPool
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.renderer import DEFAULT_ROI, RenderSettings
from eyehil.protocols.enums import Eye
from eyehil.protocols.images import ImageChunks

U32 = 1 << 32


@dataclass(frozen=True)
class FrameOptions:
    """How a device streams images: noise seed, crop per eye (w, h) px, appearance, bytes allowed downstream."""

    seed: int = 0
    crop_px: tuple[int, int] = DEFAULT_ROI
    settings: RenderSettings = field(default_factory=RenderSettings)
    budget_bytes: int = 256 * 1024
    workers: int = 0  # render processes (0: render on the device's thread)
    ahead: int = 4  # with workers: exposures in flight at most (rendering, rendered, or chunks waiting)
    kind: str = "process"  # render workers: "process" or "thread" (`render_pool`)

    def __post_init__(self) -> None:
        if not 1 <= self.ahead <= 64 or self.workers < 0 or self.budget_bytes < 1:
            raise ValueError("frame options: ahead must be in 1..64, workers >= 0, budget_bytes >= 1")


class FrameStream:
    """Images of the exposures of a stream, their chunks waiting for the link, and the counters."""

    def __init__(self, renderer: ExposureRenderer, tracked: tuple[Eye, ...], options: FrameOptions | None = None
                 ) -> None:
        """Draw with `renderer`; `tracked`: the subject's eyes in the order of its channels."""
        self.renderer, self.tracked, self.options = renderer, tracked, options or FrameOptions()
        self.sent = self.dropped = self.render_failures = 0
        self.on_done: Callable[[], None] | None = None  # called from a pool thread when an image is rendered
        self._pool = RenderPool(renderer, self.options.workers, self.options.kind, on_done=self._done)  # start now
        self._sel: Selection | None = None
        self._ahead: deque[tuple[int, int, list[tuple[Eye, Future]]]] = deque()  # (frame id, time, images)
        self._queue: deque[tuple[ImageChunks, int, bool]] = deque()  # images with chunks not yet released: their
        # exposure's timestamp, last image of its exposure
        self._queued_exposures = 0  # exposures with chunks in `_queue`
        self._open: dict[Eye, np.ndarray] = {}  # each eye's last row with open eyes (drawn shut in blinks)
        self._downstream = 0

    @classmethod
    def for_subject(cls, subject: Subject, tracked: tuple[Eye, ...], options: FrameOptions | None = None
                    ) -> FrameStream | None:
        """The image stream of `subject`, or None if its solver carries no appearance channels."""
        if not isinstance(subject.solver, AppearanceSolver):
            return None
        options = options or FrameOptions()
        return cls(ExposureRenderer.for_subject(subject, options.settings), tracked, options)

    @property
    def pending(self) -> bool:
        """Images are rendering or chunks wait to be released."""
        return bool(self._queue or self._ahead)

    @property
    def capacity(self) -> int:
        """Exposures that may be in flight."""
        return self.options.ahead if self.options.workers else 1

    @property
    def room(self) -> int:
        """Exposures that may still start (rendering ahead)."""
        return max(0, self.capacity - len(self._ahead) - self._queued_exposures)

    def start(self, selection: Selection) -> None:
        """A stream of `selection` begins."""
        self._sel = selection
        self._queue.clear()
        self._ahead.clear()
        self._queued_exposures = 0
        self._open.clear()

    def _done(self) -> None:
        if self.on_done is not None:
            self.on_done()

    def stop(self) -> None:
        """The stream ends: images not wholly released are abandoned."""
        self.dropped += len(self._queue)
        for _, _, images in self._ahead:
            for _, future in images:
                future.cancel()
            self.dropped += len(images)
        self._queue.clear()
        self._ahead.clear()
        self._queued_exposures = 0
        self._sel = None

    def wait_rendered(self, timeout: float | None = None) -> bool:
        """Wait until every image in flight is rendered (tests, tools); True if they all are."""
        futures = [f for _, _, images in self._ahead for _, f in images]
        return not wait(futures, timeout=timeout).not_done

    def close(self) -> None:
        """Stop the render workers; idempotent."""
        self._pool.close()

    def _per_exposure(self) -> int:
        return 0 if self._sel is None else len(self._sel.eyes) if self._sel.roi is None else 1

    def skip(self, count: int) -> None:
        """`count` exposures were skipped: their images are dropped."""
        self.dropped += count * self._per_exposure()

    def downstream(self, backlog: int) -> None:
        """At a poll: `backlog` bytes wait in the link."""
        self._downstream = backlog

    def offer(self, exposures: Exposures) -> None:
        """The exposures just taken: start the newest as far as there is room; drop the other images."""
        if self._sel is None or len(exposures) == 0:
            return
        start = min(self.room, len(exposures)) if self.options.workers else int(self.room > 0)
        self.dropped += (len(exposures) - start) * self._per_exposure()
        for k in range(len(exposures) - start, len(exposures)):
            self._submit(int(exposures.batch.frame_id[k]), int(exposures.time_us[k]), exposures.values[k],
                         bool(exposures.blink[k]))
        self._collect()

    def _submit(self, frame_id: int, time_us: int, values: np.ndarray, blink: bool) -> None:
        """Start rendering the images of one exposure (`values` (E', C) of the tracked eyes)."""
        sel, seed, pool = self._sel, self.options.seed, self._pool
        rows = np.stack([self._row(eye, values, blink) for eye in sel.eyes])
        if sel.roi is None:
            jobs = [(eye, RenderJob(frame_id, int(eye), rows, seed, sel.leds, eye_index=i, size=self.options.crop_px))
                    for i, eye in enumerate(sel.eyes)]
        else:
            jobs = [(Eye.BOTH, RenderJob(frame_id, int(Eye.BOTH), rows, seed, sel.leds, region=sel.roi,
                                         eye_indices=tuple(range(len(rows)))))]
        self._ahead.append((frame_id, time_us, [(eye, pool.submit(job)) for eye, job in jobs]))

    def _collect(self) -> None:
        """Move the chunks of rendered exposures, oldest first, to the release queue (in exposure order)."""
        while self._ahead and all(f.done() for _, f in self._ahead[0][2]):
            frame_id, time_us, images = self._ahead.popleft()
            chunks: list[ImageChunks] = []
            for eye, future in images:
                try:
                    rendered = future.result()
                except Exception:  # a worker died or the image failed: dropped, counted, the stream goes on
                    self.render_failures += 1
                    self.dropped += 1
                    logging.getLogger(__name__).exception("frame %d of eye %s not rendered", frame_id, eye)
                    continue
                chunks.append(ImageChunks(frame_id, eye, rendered.image, rendered.roi_xy))
            if chunks:
                self._queue.extend((c, time_us, k == len(chunks) - 1) for k, c in enumerate(chunks))
                self._queued_exposures += 1

    def _row(self, eye: Eye, values: np.ndarray, blink: bool) -> np.ndarray:
        """What to draw of `eye`: its channels, or during a blink its last open row with the lids shut."""
        if eye not in self.tracked:
            return np.full(values.shape[-1], np.nan)
        row = values[self.tracked.index(eye)]
        if not blink:
            self._open[eye] = row
            return row
        last = self._open.get(eye)
        return row if last is None else closed(last, self.renderer.layout)

    def release(self, queued: int, seq: int) -> tuple[bytes, int]:
        """Encode waiting chunks, numbered from `seq`, while the bytes downstream (plus `queued`, the core's output
        not yet read) stay under the budget; return the bytes and how many chunks they hold."""
        self._collect()
        frames: list[bytes] = []
        size = count = 0  # bytes and chunks in `frames`
        while self._queue and (room := self.options.budget_bytes - self._downstream - queued - size) > 0:
            image, time_us, last = self._queue[0]
            data, n = image.wire((seq + count) % U32, time_us, room)
            frames.append(data)
            size += len(data)
            count += n
            if image.done:
                self._queue.popleft()
                self.sent += 1
                self._queued_exposures -= last
        self._downstream += size
        return b"".join(frames), count
