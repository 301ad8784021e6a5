"""The device's image stream: which exposures become FRAME_CHUNKs, and when their chunks go out.

Images (docs/protocol.md sections 5.3 and 7, FRAME_CHUNK), rendered by `frames` from the exposure's
observation (`camera.Exposures.values`) with the generator `frames.exposure_rng(seed, frame_id, eye)`:

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
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver, closed
from eyehil.emulator.device.camera import Exposures, Selection
from eyehil.emulator.device.frames import ExposureRenderer, exposure_rng, render_exposure, render_region
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.renderer import DEFAULT_ROI, Frame, RenderSettings
from eyehil.protocols.enums import Eye
from eyehil.protocols.images import split_image
from eyehil.protocols.native import encode
from eyehil.protocols.samples import FrameChunk

U32 = 1 << 32


@dataclass(frozen=True)
class FrameOptions:
    """How a device streams images: noise seed, crop per eye (w, h) px, appearance, bytes allowed downstream."""

    seed: int = 0
    crop_px: tuple[int, int] = DEFAULT_ROI
    settings: RenderSettings = field(default_factory=RenderSettings)
    budget_bytes: int = 256 * 1024


class FrameStream:
    """Images of the exposures of a stream, their chunks waiting for the link, and the counters."""

    def __init__(self, renderer: ExposureRenderer, tracked: tuple[Eye, ...], options: FrameOptions | None = None
                 ) -> None:
        """Draw with `renderer`; `tracked`: the subject's eyes in the order of its channels."""
        self.renderer, self.tracked, self.options = renderer, tracked, options or FrameOptions()
        self.sent = self.dropped = 0
        self._sel: Selection | None = None
        self._queue: deque[tuple[FrameChunk, int]] = deque()  # chunks not yet released, with their timestamp
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
        """Chunks wait to be released."""
        return bool(self._queue)

    def start(self, selection: Selection) -> None:
        """A stream of `selection` begins."""
        self._sel = selection
        self._queue.clear()
        self._open.clear()

    def stop(self) -> None:
        """The stream ends: images not wholly released are abandoned."""
        self.dropped += sum(c.chunk_index == c.chunk_count - 1 for c, _ in self._queue)
        self._queue.clear()
        self._sel = None

    def _per_exposure(self) -> int:
        return 0 if self._sel is None else len(self._sel.eyes) if self._sel.roi is None else 1

    def skip(self, count: int) -> None:
        """`count` exposures were skipped: their images are dropped."""
        self.dropped += count * self._per_exposure()

    def downstream(self, backlog: int) -> None:
        """At a poll: `backlog` bytes wait in the link."""
        self._downstream = backlog

    def offer(self, exposures: Exposures) -> None:
        """The exposures just taken: render the newest if no chunk is waiting; drop the other images."""
        if self._sel is None or len(exposures) == 0:
            return
        start = not self._queue
        self.dropped += (len(exposures) - start) * self._per_exposure()
        if start:
            self._render(int(exposures.batch.frame_id[-1]), int(exposures.time_us[-1]), exposures.values[-1],
                         bool(exposures.blink[-1]))

    def _render(self, frame_id: int, time_us: int, values: np.ndarray, blink: bool) -> None:
        """Queue the chunks of the images of one exposure (`values` (E', C) of the tracked eyes)."""
        sel, seed = self._sel, self.options.seed
        rows = np.stack([self._row(eye, values, blink) for eye in sel.eyes])
        images: list[tuple[Eye, Frame]] = []
        if sel.roi is None:
            for i, eye in enumerate(sel.eyes):
                frame = render_exposure(self.renderer, rows, i, exposure_rng(seed, frame_id, eye), leds=sel.leds,
                                        size=self.options.crop_px)
                images.append((eye, frame))
        else:
            rng = exposure_rng(seed, frame_id, Eye.BOTH)
            images.append((Eye.BOTH, render_region(self.renderer, rows, tuple(range(len(rows))), sel.roi, rng,
                                                   leds=sel.leds)))
        for eye, frame in images:
            self._queue.extend((c, time_us) for c in split_image(frame_id, eye, frame.image, frame.roi_xy))

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
        out, n = bytearray(), 0
        while self._queue and self._downstream + queued + len(out) < self.options.budget_bytes:
            chunk, time_us = self._queue.popleft()
            out += encode(chunk, (seq + n) % U32, time_us)
            n += 1
            self.sent += chunk.chunk_index == chunk.chunk_count - 1
        self._downstream += len(out)
        return bytes(out), n
