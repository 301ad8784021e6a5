"""Rendering camera images off the device's thread: inline, in a thread pool, or in worker processes.

A device thread that renders its own images holds the interpreter lock for most of each image (the renderer is
numpy on small arrays: much of its time is Python), so the thread that streams samples and images waits
for it. `RenderPool` takes `RenderJob`s (one image: the exposure's rows, the window, the generator's key) and
returns `concurrent.futures.Future`s of `Rendered` (8-bit image, window origin, and, for a facade that
publishes encoded images, the encoded bytes):

- ``workers=0``: rendered at `submit` on the caller's thread (the future is already done; deterministic);
- ``kind="process"`` (default): `workers` processes (started with ``spawn``, so no thread or socket of the
  device is inherited), each holding the `ExposureRenderer` given at start; a job crosses a pipe as its rows
  (about 3 kB) and comes back as its pixels (77 kB for 320 x 240). The constructor waits until the workers
  run (they import numpy, OpenCV and eyehil: seconds), so a device serves images from its first exposure.
  As with any ``spawn`` pool, a script that makes one must guard its entry point
  (``if __name__ == "__main__":``); the `eyehil` command and pytest do;
- ``kind="thread"``: a thread pool in this process (OpenCV and numpy's large operations release the lock,
  the rest does not: `python -m bench zmq` compares the kinds).

Every image is a function of its job alone (`frames.exposure_noise(seed, frame_id, eye)`), so every kind gives
the same pixels. The pool bounds nothing by itself: its users keep at most a fixed number of jobs in flight
(`frame_stream.FrameStream`, `pupil.frames.FramePublisher`) and count what they drop. `on_done`, if given, is
called (from a pool thread) whenever a job finishes, so a device thread waiting on a clock can wake.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from eyehil.emulator.device.frames import ExposureRenderer, exposure_noise, render_exposure, render_region
from eyehil.parallel import exit_with_parent

MAX_RENDER_WORKERS = 8
START_TIMEOUT_S = 120.0  # a process pool waits this long for its workers to import and start (a busy machine)
KINDS = ("process", "thread")
_WORKER_RENDERER: ExposureRenderer | None = None  # a worker process's renderer (`_init_worker`)


@dataclass(frozen=True)
class RenderJob:
    """One image of one exposure: `rows` (E', C) channels of the eyes drawn; `eye_index` draws that row as a crop
    of `size` (w, h) px around its pupil (`frames.render_exposure`), else `region` (x, y, w, h) px shows the rows
    `eye_indices` (`frames.render_region`). Noise: `exposure_noise(seed, frame_id, eye)`. `fmt`: also encode the
    image (`encode`, e.g. the ZeroMQ facade's gray, bgr, jpeg)."""

    frame_id: int
    eye: int
    rows: np.ndarray
    seed: int = 0
    leds: int | None = None
    eye_index: int | None = None
    size: tuple[int, int] = (320, 240)
    region: tuple[int, int, int, int] | None = None
    eye_indices: tuple[int, ...] = ()
    fmt: str | None = None
    pixels: bool = True  # False (with `fmt`): return only the encoding, so a worker's pipe carries half as much


@dataclass(frozen=True)
class Rendered:
    """An image (H, W) uint8 whose top-left pixel is sensor pixel `roi_xy` (None if the job asked only for the
    encoding), and its encoding if asked for."""

    image: np.ndarray | None
    roi_xy: tuple[int, int]
    encoded: bytes | None = None


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


def render_job(renderer: ExposureRenderer, job: RenderJob) -> Rendered:
    """Render `job` (any thread or process)."""
    rng = exposure_noise(job.seed, job.frame_id, job.eye)
    if job.region is None:
        frame = render_exposure(renderer, job.rows, int(job.eye_index or 0), rng, leds=job.leds, size=job.size)
    else:
        frame = render_region(renderer, job.rows, job.eye_indices, job.region, rng, leds=job.leds)
    encoded = None
    if job.fmt is not None:
        encoded = encode_image(frame.image, job.fmt)
    image = frame.image if job.pixels or encoded is None else None
    return Rendered(image, tuple(int(v) for v in frame.roi_xy), encoded)


def _init_worker(renderer: ExposureRenderer, setup: Callable[[], None] | None = None, parent: int | None = None
                 ) -> None:
    global _WORKER_RENDERER
    _WORKER_RENDERER = renderer
    # One OpenCV thread: the pool is the parallelism. OpenCV's own pool (one thread per core) made each small
    # blur wake threads that fought the device's process for the two cores: 640 x 480 frames over ZeroMQ went
    # from 127-142 to 193-197 of 200 per second (python -m bench zmq, idle, 2 cores).
    cv2.setNumThreads(1)
    exit_with_parent(parent)  # a killed device leaves no render process behind
    if setup is not None:
        setup()


def _render_in_worker(job: RenderJob) -> Rendered:
    assert _WORKER_RENDERER is not None, "worker not initialised"
    return render_job(_WORKER_RENDERER, job)


def _call_in_worker(fn: Callable[..., Any], args: tuple) -> Any:
    assert _WORKER_RENDERER is not None, "worker not initialised"
    return fn(_WORKER_RENDERER, *args)


def _ready() -> bool:
    return True


class RenderPool:
    """See the module docstring; `close` (or `with`) stops the workers."""

    def __init__(self, renderer: ExposureRenderer, workers: int = 1, kind: str = "process",
                 on_done: Callable[[], None] | None = None, setup: Callable[[], None] | None = None) -> None:
        """Render with `renderer` in `workers` workers of `kind` (0: inline); `setup` (picklable) runs once in
        each worker process as it starts (e.g. to open the socket a `call` publishes on)."""
        if not 0 <= workers <= MAX_RENDER_WORKERS or kind not in KINDS:
            raise ValueError(f"render workers must be in 0..{MAX_RENDER_WORKERS} and kind one of {KINDS}")
        self.renderer, self.workers, self.kind, self.on_done = renderer, workers, kind, on_done
        self._executor: Executor | None = None
        if workers and kind == "process":
            self._executor = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=_init_worker, initargs=(renderer, setup, os.getpid()))
            warm = [self._executor.submit(_ready) for _ in range(workers)]  # start the workers now
            done, _ = wait(warm, timeout=START_TIMEOUT_S)
            if len(done) < workers or not all(f.result() for f in done):
                self.close()
                raise RuntimeError(f"the render workers did not start within {START_TIMEOUT_S:.0f} s")
        elif workers:
            self._executor = ThreadPoolExecutor(workers, thread_name_prefix="eyehil-render")

    def submit(self, job: RenderJob) -> Future:
        """The future `Rendered` of `job`."""
        if self._executor is None:
            future: Future = Future()
            future.set_result(render_job(self.renderer, job))
            return future
        if self.kind == "process":
            return self._watched(self._executor.submit(_render_in_worker, job))
        return self._watched(self._executor.submit(render_job, self.renderer, job))

    def call(self, fn: Callable[..., Any], *args: Any) -> Future:
        """The future of `fn(renderer, *args)` in a worker process (`fn` and `args` picklable); only for
        ``kind="process"`` with workers."""
        if self._executor is None or self.kind != "process":
            raise ValueError("RenderPool.call needs worker processes")
        return self._watched(self._executor.submit(_call_in_worker, fn, args))

    def _watched(self, future: Future) -> Future:
        """`future`, with `on_done` called when it finishes."""
        if self.on_done is not None:
            future.add_done_callback(lambda _: self.on_done())
        return future

    def close(self) -> None:
        """Stop the workers (jobs not started are cancelled); idempotent."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None

    def __enter__(self) -> RenderPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
