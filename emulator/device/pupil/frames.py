"""`frame.eye.<id>` for the ZeroMQ facade: eye images rendered and published on their own thread.

Which exposures: every k-th, k = max(1, round(rate / frame_rate)) (by the camera's frame id), while frame
publishing is on. Each image is the eye's fixed window (`zmq_datums.EyeWindow`) drawn by
`eyehil.emulator.device.frames.render_region` from the exposure's channels with every tracked eye in it (during a
blink: the eye's last open row with the lids shut, `appearance.closed`), noise from
`frames.exposure_rng(seed, frame_id, eye)`. Eyes sharing a window (the full sensor) share one rendering.

Payload (`eyehil.protocols.pupil.frame_datum`): {topic, width, height, index, timestamp, format} and one raw frame:
``gray`` H x W bytes, ``bgr`` H x W x 3 (the gray value in each channel), ``jpeg`` (`cv2.imencode`, a
one-channel JPEG). `index` counts the images offered per eye, including those dropped, so a subscriber sees
gaps. The core thread `offer`s; the frame thread ("eyehil-zmq-frames") renders and publishes on its own PUB.
Capacity (`ImageThread`, shared with the world view, `pupil/world.py`): at most `QUEUE` exposures wait; an
exposure offered to a full queue is dropped (`dropped` counts images), so rendering never delays the pupil datums.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import cv2
import numpy as np
import zmq

from eyehil.emulator.device.appearance import closed
from eyehil.emulator.device.frames import ExposureRenderer, exposure_rng, render_region
from eyehil.emulator.device.pupil.datums import EyeWindow
from eyehil.protocols.pupil import frame_datum, pack

QUEUE = 2
POLL_S = 0.1


@dataclass(frozen=True)
class FrameJob:
    """One exposure to draw: camera frame id, Pupil time (s), channels (E, C) per tracked eye, image index
    per window, and the format."""

    frame_id: int
    timestamp: float
    rows: np.ndarray
    indices: tuple[int, ...]
    fmt: str


def encode_image(image: np.ndarray, fmt: str) -> bytes:
    """The raw frame of an 8-bit gray image (H, W) in `fmt` (gray, bgr, jpeg)."""
    if fmt == "bgr":
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR).tobytes()
    if fmt == "jpeg":
        ok, data = cv2.imencode(".jpg", image)
        if not ok:
            raise ValueError("JPEG encoding failed")
        return data.tobytes()
    return np.ascontiguousarray(image).tobytes()


class ImageThread:
    """A thread that renders and publishes images on its own PUB (connected to the backbone's XSUB), fed
    through a queue of at most `QUEUE` jobs: a job offered to a full queue is dropped and its `images`
    counted in `dropped`, so the offering thread never waits. Subclasses draw and send in `_publish(job)`."""

    THREAD_NAME = "eyehil-zmq-images"

    def __init__(self, context: zmq.Context, endpoint: str, hwm: int) -> None:
        self.dropped = self.published = 0
        self._queue: queue.Queue = queue.Queue(QUEUE)
        self._stop = threading.Event()
        self._pub = context.socket(zmq.PUB)
        self._pub.setsockopt(zmq.LINGER, 0)
        self._pub.setsockopt(zmq.SNDHWM, hwm)
        self._pub.connect(endpoint)
        self._thread = threading.Thread(target=self._run, name=self.THREAD_NAME, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _submit(self, job: object, images: int) -> None:
        """Queue `job` (worth `images` images), or drop and count it if the queue is full."""
        try:
            self._queue.put_nowait((job, images))
        except queue.Full:
            self.dropped += images

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    job, _ = self._queue.get(timeout=POLL_S)
                except queue.Empty:
                    continue
                self._publish(job)
        finally:
            self._pub.close(linger=0)

    def _publish(self, job: object) -> None:
        raise NotImplementedError

    def _send(self, message: dict) -> None:
        self._pub.send_multipart(pack(message), copy=False)
        self.published += 1

    def close(self) -> None:
        """Stop the thread (jobs waiting are dropped and counted) and close the socket."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        else:
            self._pub.close(linger=0)
        while True:
            try:
                self.dropped += self._queue.get_nowait()[1]
            except queue.Empty:
                break


class FramePublisher(ImageThread):
    """Renders and publishes eye images; see the module docstring."""

    THREAD_NAME = "eyehil-zmq-frames"

    def __init__(self, context: zmq.Context, endpoint: str, renderer: ExposureRenderer, windows: list[EyeWindow],
                 *, seed: int = 0, hwm: int = 1000) -> None:
        """Publish to the backbone's XSUB at `endpoint`; call `start`, then `close`."""
        super().__init__(context, endpoint, hwm)
        self.renderer, self.windows, self.seed = renderer, windows, seed
        self._counts = [0] * len(windows)
        self._open: dict[int, np.ndarray] = {}  # last open-eye row per tracked eye

    def offer(self, frame_id: int, timestamp: float, values: np.ndarray, blink: bool, fmt: str) -> None:
        """An exposure whose images are due (`values` (E, C) of the tracked eyes); called by the core thread."""
        rows = np.stack([self._row(e, values[e], blink) for e in range(len(values))])
        indices = tuple(self._counts)
        self._counts = [c + 1 for c in self._counts]
        self._submit(FrameJob(frame_id, timestamp, rows, indices, fmt), len(self.windows))

    def _row(self, e: int, row: np.ndarray, blink: bool) -> np.ndarray:
        if not blink:
            self._open[e] = row
            return row
        last = self._open.get(e)
        return row if last is None else closed(last, self.renderer.layout)

    def _publish(self, job: FrameJob) -> None:
        """Render the job's windows (once per distinct window) and send one message per eye."""
        drawn: dict[tuple[int, int, int, int], bytes] = {}
        eyes = tuple(range(len(job.rows)))
        for win, index in zip(self.windows, job.indices, strict=True):
            region = (win.x0, win.y0, win.width, win.height)
            if region not in drawn:
                rng = exposure_rng(self.seed, job.frame_id, win.eye_id)
                frame = render_region(self.renderer, job.rows, eyes, region, rng)
                drawn[region] = encode_image(frame.image, job.fmt)
            self._send(frame_datum(win.eye_id, index, job.timestamp, win.width, win.height, job.fmt, drawn[region]))
