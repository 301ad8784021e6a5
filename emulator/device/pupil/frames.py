"""`frame.eye.<id>` for the ZeroMQ facade: eye images rendered and published on their own thread.

Which exposures: every k-th, k = max(1, round(rate / frame_rate)) (by the camera's frame id), while frame
publishing is on. Each image is the eye's fixed window (`zmq_datums.EyeWindow`) drawn by
`eyehil.emulator.device.frames.render_region` from the exposure's channels with every tracked eye in it (during a
blink: the eye's last open row with the lids shut, `appearance.closed`), noise from
`frames.exposure_noise(seed, frame_id, eye)`. Eyes sharing a window (the full sensor) share one rendering.

Payload (`eyehil.protocols.pupil.frame_datum`): {topic, width, height, index, timestamp, format} and one raw frame:
``gray`` H x W bytes, ``bgr`` H x W x 3 (the gray value in each channel), ``jpeg`` (`cv2.imencode`, a
one-channel JPEG). `index` counts the images offered per eye, including those dropped, so a subscriber sees
gaps. The core thread `offer`s; the frame thread ("eyehil-zmq-frames") hands the exposures to a
`render_pool.RenderPool` and publishes the images, in exposure order, on its own PUB. With ``workers=0`` the
frame thread renders them itself, sharing the interpreter lock with the thread that publishes the pupil
datums; with ``workers`` >= 1 they are rendered (and encoded) in that many processes (``kind="process"``) or
pool threads (``kind="thread"``), so the datums' thread is not held up. Render processes given the backbone's
TCP endpoint (`tcp_endpoint`, the XSUB that clients publish to) publish their images themselves on a PUB of
their own (`connect_worker`, `publish_in_worker`): only the job (about 3 kB of channels) crosses the pipe and
a count comes back, so neither the image bytes nor their packing touch this process's interpreter lock. One
process publishes in exposure order; with several, images of neighbouring exposures can arrive out of order
(their `index` tells). Capacity: at most `QUEUE` exposures
wait for the frame thread and `ahead` render in the pool; an exposure offered to a full queue is dropped
(`dropped` counts images, as it counts images whose rendering failed), so rendering never delays the datums.
`ImageThread` is the simpler bounded thread of the world view (`pupil/world.py`): at most `IMAGE_QUEUE` jobs wait, a
job offered to a full queue is dropped and counted, and the thread draws each itself.
"""

from __future__ import annotations

import atexit
import logging
import queue
import threading
from collections import deque
from concurrent.futures import Future
from dataclasses import dataclass
from functools import partial

import numpy as np
import zmq

from eyehil.emulator.device.appearance import closed
from eyehil.emulator.device.frames import ExposureRenderer
from eyehil.emulator.device.pupil.datums import EyeWindow
from eyehil.emulator.device.render_pool import RenderJob, RenderPool, encode_image, render_job
from eyehil.protocols.pupil import frame_datum, pack

# encode_image lives in render_pool (workers encode)
__all__ = ["FrameJob", "FramePublisher", "ImageThread", "encode_image"]

QUEUE = 8  # exposures waiting for the frame thread at most
IMAGE_QUEUE = 2  # jobs waiting for an `ImageThread` (the world view draws on that thread) at most
AHEAD = 8  # exposures rendering in the pool at most (with workers): 40 ms at 200 Hz. With 2 and 4, a render
# process held back by the system for 30 ms dropped images (python -m bench zmq, 2 cores)
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


class ImageThread:
    """A thread that renders and publishes images on its own PUB (connected to the backbone's XSUB), fed
    through a queue of at most `IMAGE_QUEUE` jobs: a job offered to a full queue is dropped and its `images`
    counted in `dropped`, so the offering thread never waits. Subclasses draw and send in `_publish(job)`."""

    THREAD_NAME = "eyehil-zmq-images"

    def __init__(self, context: zmq.Context, endpoint: str, hwm: int) -> None:
        self.dropped = self.published = 0
        self._queue: queue.Queue = queue.Queue(IMAGE_QUEUE)
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


_WORKER_PUB: zmq.Socket | None = None  # a render process's own PUB to the backbone (`connect_worker`)


def connect_worker(endpoint: str, hwm: int) -> None:
    """In a render process, as it starts: its PUB, connected to the backbone's XSUB at `endpoint` (TCP)."""
    global _WORKER_PUB
    sock = zmq.Context.instance().socket(zmq.PUB)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.SNDHWM, hwm)
    sock.connect(endpoint)
    _WORKER_PUB = sock
    atexit.register(sock.close, 0)


def publish_in_worker(renderer: ExposureRenderer, job: RenderJob, heads: tuple[tuple[int, int], ...],
                      timestamp: float) -> int:
    """In a render process: render and encode `job`, then publish it on the process's PUB once per (eye id,
    index) of `heads` (the eyes whose window it is); the number of messages sent."""
    assert _WORKER_PUB is not None, "render process not connected"
    encoded = render_job(renderer, job).encoded
    _, _, width, height = job.region
    for eye_id, index in heads:
        _WORKER_PUB.send_multipart(pack(frame_datum(eye_id, index, timestamp, width, height, job.fmt, encoded)),
                                   copy=False)
    return len(heads)


class FramePublisher:
    """Renders and publishes eye images; see the module docstring."""

    def __init__(self, context: zmq.Context, endpoint: str, renderer: ExposureRenderer, windows: list[EyeWindow],
                 *, seed: int = 0, hwm: int = 1000, workers: int = 0, kind: str = "process",
                 tcp_endpoint: str | None = None) -> None:
        """Publish to the backbone's XSUB at `endpoint`; render in `workers` processes or threads (`kind`; 0: on
        the frame thread); render processes publish themselves to the XSUB's `tcp_endpoint` when it is given
        (module docstring); call `start`, then `close`."""
        self.renderer, self.windows, self.seed = renderer, windows, seed
        self.dropped = self.published = 0
        self._counts = [0] * len(windows)
        self._open: dict[int, np.ndarray] = {}  # last open-eye row per tracked eye
        self._queue: queue.Queue[FrameJob] = queue.Queue(QUEUE)
        self._stop = threading.Event()
        self._event = threading.Event()  # a job was offered or an image rendered
        self._ahead = AHEAD if workers else 1
        self._pub = context.socket(zmq.PUB)
        self._pub.setsockopt(zmq.LINGER, 0)
        self._pub.setsockopt(zmq.SNDHWM, hwm)
        self._pub.connect(endpoint)
        self._pending: deque[tuple[FrameJob, dict[tuple[int, int, int, int], Future]]] = deque()
        self._regions: dict[tuple[int, int, int, int], list[int]] = {}  # window -> the eyes (positions) it shows
        for k, win in enumerate(windows):
            self._regions.setdefault(win.region, []).append(k)
        self._direct = bool(workers) and kind == "process" and tcp_endpoint is not None
        setup = partial(connect_worker, tcp_endpoint, hwm) if self._direct else None
        self._pool = RenderPool(renderer, workers, kind, on_done=self._event.set, setup=setup)
        self._thread = threading.Thread(target=self._run, name="eyehil-zmq-frames", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def offer(self, frame_id: int, timestamp: float, values: np.ndarray, blink: bool, fmt: str) -> None:
        """An exposure whose images are due (`values` (E, C) of the tracked eyes); called by the core thread."""
        rows = np.stack([self._row(e, values[e], blink) for e in range(len(values))])
        indices = tuple(self._counts)
        self._counts = [c + 1 for c in self._counts]
        try:
            self._queue.put_nowait(FrameJob(frame_id, timestamp, rows, indices, fmt))
        except queue.Full:
            self.dropped += len(self.windows)
        else:
            self._event.set()

    def _row(self, e: int, row: np.ndarray, blink: bool) -> np.ndarray:
        if not blink:
            self._open[e] = row
            return row
        last = self._open.get(e)
        return row if last is None else closed(last, self.renderer.layout)

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._event.wait(POLL_S)
                self._event.clear()
                while len(self._pending) < self._ahead:
                    try:
                        job = self._queue.get_nowait()
                    except queue.Empty:
                        break
                    self._pending.append((job, self._submit(job)))
                while self._pending and all(f.done() for f in self._pending[0][1].values()):
                    self._publish(*self._pending.popleft())
        finally:
            self._pub.close(linger=0)

    def _submit(self, job: FrameJob) -> dict[tuple[int, int, int, int], Future]:
        """Start rendering the job's distinct windows (eyes sharing a window share one rendering)."""
        eyes = tuple(range(len(job.rows)))
        futures: dict[tuple[int, int, int, int], Future] = {}
        for region, members in self._regions.items():
            render = RenderJob(job.frame_id, self.windows[members[0]].eye_id, job.rows, self.seed, region=region,
                               eye_indices=eyes, fmt=job.fmt, pixels=False)
            if self._direct:
                heads = tuple((self.windows[k].eye_id, job.indices[k]) for k in members)
                futures[region] = self._pool.call(publish_in_worker, render, heads, job.timestamp)
            else:
                futures[region] = self._pool.submit(render)
        return futures

    def _publish(self, job: FrameJob, futures: dict[tuple[int, int, int, int], Future]) -> None:
        """Send one message per eye of a rendered job (an image whose rendering failed is dropped, counted);
        with render processes that publish themselves, count what they sent."""
        if self._direct:
            for region, future in futures.items():
                try:
                    self.published += future.result()
                except Exception:
                    logging.getLogger(__name__).exception("frame %d not rendered", job.frame_id)
                    self.dropped += len(self._regions[region])
            return
        for win, index in zip(self.windows, job.indices, strict=True):
            future = futures[win.region]
            try:
                data = future.result().encoded
            except Exception:
                logging.getLogger(__name__).exception("frame %d of eye %d not rendered", job.frame_id, win.eye_id)
                self.dropped += 1
                continue
            message = frame_datum(win.eye_id, index, job.timestamp, win.width, win.height, job.fmt, data)
            self._pub.send_multipart(pack(message), copy=False)
            self.published += 1

    def close(self) -> None:
        """Stop the thread and the pool (images waiting or rendering are dropped) and close the socket."""
        self._stop.set()
        self._event.set()
        if self._thread.is_alive():
            self._thread.join()
        else:
            self._pub.close(linger=0)
        self._pool.close()
        self.dropped += (self._queue.qsize() + len(self._pending)) * len(self.windows)
        self._pending.clear()
