"""The view's host: one thread that owns the tracker, streams, runs the page's commands and publishes.

`ViewSession(url, publish, ...)` connects to `url` (any link of `eyehil.drivers.links`), handshakes, syncs the
clocks, configures the stream (`stream`: "features"; "both" = features and camera images; "frames" = images
only, the host detects the features with `eyehil.drivers.frames.FrameReader`; "detect" = both streamed, the host
detects and the device's FEATURES are drawn as the reference, on the emulator the ground truth; "auto" = both if
the device streams images) and starts it. It publishes dicts (`payload`) and binary image messages through
`publish` (thread-safe, e.g. `Hub.publish_threadsafe`): "hello" (the device), "state" (twice a second and on
every change), "tick" (`tick_hz` times a second: the samples since the last tick, the last record of each eye,
gaze, target and health), images (at most `max_image_hz` per eye in device time), "script", "calibration".

Commands (`submit`, bounded queue): start, stop, script (fixations | pursuit | grid | none), calibrate
(guestrin | blignaut; `eyehil.drivers.calibration.calibrate` through an `ObservedTracker`, so its samples and targets
show live), blink (only with an `oracle`: a device-side helper given in-process, e.g. by ``eyehil emulate
--view``; the wire has no blink command). A link that fails or a device that stops answering makes the
session "disconnected"; it reopens the URL every `retry_s` and resumes streaming when the device is back.
Screen positions are STIMULUS mm (top-left origin, x right, y down); gaze estimates are converted from the
geometry's screen mm with `eyehil.drivers.calibration.screen_to_stimulus`.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

from eyehil.drivers.calibration import METHODS, Plan, Result, calibrate
from eyehil.drivers.errors import LinkError, TrackerError, TrackerTimeoutError
from eyehil.drivers.frames import FrameReader
from eyehil.drivers.gaze.geometry import TrackerGeometry
from eyehil.drivers.view.live import LiveStream, estimate_gaze
from eyehil.drivers.view.observed import ObservedTracker, open_observed
from eyehil.drivers.view.payload import calibration_message, hello_message, xy
from eyehil.drivers.view.scripts import NAMES, GazeScript
from eyehil.drivers.wire import ReceivedImage, Sample
from eyehil.protocols.enums import Capability, StreamSelect

STREAMS = {"features": StreamSelect.FEATURES, "both": StreamSelect.BOTH, "frames": StreamSelect.FRAMES,
           "detect": StreamSelect.BOTH}
HOST_DETECTS = ("frames", "detect")  # modes in which the host finds the features in the images
COMMANDS = 16
STATUS_EVERY_S = 1.0
MAX_READS = 32  # link reads (of up to 64 kB) per step before the samples are processed


class ViewSession:
    """See the module docstring."""

    def __init__(self, url: str, publish: Callable[[dict | bytes], None], *, geometry: TrackerGeometry | None = None,
                 stream: str = "auto", rate_hz: int | None = None, timeout: float = 2.0, autostart: bool = True,
                 tick_hz: float = 30.0, max_image_hz: float = 120.0, retry_s: float = 0.5, oracle=None,
                 recorder=None, plan_timing: dict | None = None) -> None:
        if stream not in (*STREAMS, "auto"):
            raise ValueError(f"stream must be one of {(*STREAMS, 'auto')}, got {stream!r}")
        self.url, self.publish, self.geometry = url, publish, geometry
        self.stream_mode, self.rate_hz, self.timeout = stream, rate_hz, timeout
        self.tick_s, self.retry_s = 1 / tick_hz, retry_s
        self.oracle, self.recorder, self.plan_timing = oracle, recorder, plan_timing or {}
        self.want_streaming = autostart
        self.commands: queue.Queue[dict] = queue.Queue(COMMANDS)
        self.tracker: ObservedTracker | None = None
        self.live = LiveStream(max_image_hz)
        self.result: Result | None = None
        self.script: GazeScript | None = None
        self.error: str | None = None
        self.calibrating: str | None = None
        self.sync = None
        self.reader: FrameReader | None = None
        self._target: tuple[float, float] | None = None
        self.counters = {"commands_refused": 0, "reconnects": 0}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._reset_stream()

    # --- life ---------------------------------------------------------------------------------
    def start(self) -> ViewSession:
        self._thread = threading.Thread(target=self.run, name="eyehil-view-session", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self._disconnect(None)

    def submit(self, command: dict) -> bool:
        """Queue a page command (thread-safe); False if the queue is full."""
        try:
            self.commands.put_nowait(command)
            return True
        except queue.Full:
            self.counters["commands_refused"] += 1
            return False

    def run(self) -> None:
        last_state = 0.0
        while not self._stop.is_set():
            if time.monotonic() - last_state >= 0.5:
                self._publish_state()
                last_state = time.monotonic()
            if self.tracker is None and not self._connect():
                self._stop.wait(self.retry_s)
                continue
            try:
                self._commands()
                self._step()
            except (TrackerError, OSError) as exc:
                self._disconnect(f"{type(exc).__name__}: {exc}")

    # --- connection ---------------------------------------------------------------------------
    def _connect(self) -> bool:
        try:
            tracker = open_observed(self.url, timeout=self.timeout)
        except (TrackerError, OSError, ValueError) as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            return False
        try:
            tracker.on_sample, tracker.on_target = self._observed_sample, self._observed_target
            info = tracker.info
            self.sync = tracker.sync_clock(4) if Capability.TIME_SYNC in info.capabilities else None
            if tracker.streaming:
                tracker.stop()
            self.tracker, self.error = tracker, None
            self._configure()
            self._publish_hello()
            if self.want_streaming:
                self._start()
        except (TrackerError, OSError) as exc:
            self.tracker = None
            tracker.close(stop=False)
            self.error = f"{type(exc).__name__}: {exc}"
            return False
        self.counters["reconnects"] += 1
        self._publish_state()
        return True

    def _disconnect(self, error: str | None) -> None:
        tracker, self.tracker = self.tracker, None
        if tracker is not None:
            tracker.close(stop=error is None)
        self.error, self.calibrating = error, None
        self.live.stats.reset()
        self._publish_state()

    def _mode(self) -> str:
        """The stream mode, "auto" resolved."""
        if self.stream_mode != "auto":
            return self.stream_mode
        return "both" if Capability.FRAMES in self.tracker.info.capabilities else "features"

    def _stream_select(self) -> StreamSelect:
        return STREAMS[self._mode()]

    def _configure(self, leds: int | None = None, eyes=None) -> None:
        """CONFIGURE: the view's stream; LEDs and eyes as given (a calibration's) or the device's defaults."""
        self.tracker.configure(leds=leds, rate_hz=self.rate_hz, eyes=eyes, stream=self._stream_select())
        self.reader = None
        if self._mode() in HOST_DETECTS:
            leds_xy = self.geometry.leds[:, :2] if self.geometry is not None else None
            self.reader = FrameReader(self.tracker, led_xy_mm=leds_xy)

    def _start(self) -> None:
        self.tracker.start()
        self.want_streaming = True
        self._reset_stream()
        self._publish_state()

    def _reset_stream(self) -> None:
        self.live.reset()
        self._last_tick = self._last_status = 0.0
        self._last_sample_at = time.monotonic()
        self.device_status: dict[str, int] = {}

    # --- commands -----------------------------------------------------------------------------
    def _commands(self) -> None:
        while True:
            try:
                command = self.commands.get_nowait()
            except queue.Empty:
                return
            try:
                self._command(command)
            except (ValueError, KeyError, TypeError) as exc:
                self.error = f"command {command.get('cmd')!r} refused: {exc}"
                self._publish_state()

    def _command(self, command: dict) -> None:
        name = command.get("cmd")
        if name == "start" and not self.tracker.streaming:
            self._start()
        elif name == "stop":
            self.want_streaming = False
            if self.tracker.streaming:
                self.tracker.stop()
            self._publish_state()
        elif name == "script":
            self._set_script(str(command.get("name", "none")))
        elif name == "calibrate":
            self._calibrate(str(command.get("method", "guestrin")))
        elif name == "blink":
            if self.oracle is None:
                raise ValueError("this device cannot be made to blink from the host (no in-process emulator)")
            self.oracle.blink(min(max(float(command.get("duration_s", 0.3)), 0.05), 2.0))
        elif name not in ("start",):
            raise ValueError("unknown command")

    def _screen_size(self) -> tuple[float, float]:
        if self.geometry is None:
            raise ValueError("targets need the screen's size: give the view a geometry file (--geometry)")
        if Capability.STIMULUS not in self.tracker.info.capabilities:
            raise ValueError("this device has no simulated subject (no STIMULUS capability)")
        w, h = self.geometry.screen.size_mm
        return float(w), float(h)

    def _set_script(self, name: str) -> None:
        if name == "none":
            self.script = None
        elif name in NAMES:
            self.script = GazeScript(name, self._screen_size())
            self._script_t0, self._target, self._target_id = time.monotonic(), None, 0
        else:
            raise ValueError(f"unknown script {name!r}")
        points = [] if self.script is None else [xy(p) for p in self.script.points()]
        self.publish({"type": "script", "name": name, "points": points})

    # --- calibration --------------------------------------------------------------------------
    def _calibrate(self, method: str) -> None:
        if method not in METHODS:
            raise ValueError(f"calibration method must be one of {METHODS}")
        self._screen_size()
        self.script, self.calibrating = None, method
        self.publish({"type": "script", "name": "none", "points": []})
        self._publish_state()
        geometry, tracker = self.geometry, self.tracker
        plan = Plan.default(geometry.screen, **self.plan_timing)
        if tracker.streaming:
            tracker.stop()
        frames = self._mode() in HOST_DETECTS
        try:
            result = calibrate(tracker, geometry, method, plan, rate_hz=self.rate_hz, frames=frames)
        except (LinkError, TrackerTimeoutError):
            raise
        except (ValueError, TrackerError) as exc:  # refused, or too few usable fixations: the page says why
            self.publish({"type": "calibration", "method": method, "ok": False, "error": str(exc)})
            result = None
        finally:
            self.calibrating = None
        if result is not None:
            self.result = result
            self.publish(calibration_message(result, self.geometry.screen))
        cfg = tracker.configuration
        self._configure(leds=cfg.leds, eyes=cfg.eyes)
        if self.want_streaming:
            self._start()
        self._publish_state()

    def _observed_sample(self, sample: Sample) -> None:
        if self._stop.is_set():  # closing during a calibration: abandon it (the run loop disconnects)
            raise LinkError("the view is closing")
        if self.calibrating:
            self._process([sample])
            self._publish_tick_if_due()

    def _observed_target(self, target_id: int, x_mm: float, y_mm: float) -> None:
        self._target = (x_mm, y_mm)

    # --- streaming ----------------------------------------------------------------------------
    def _step(self) -> None:
        tracker = self.tracker
        if not tracker.streaming:
            self._stop.wait(0.02)
            if time.monotonic() - self._last_status >= STATUS_EVERY_S:
                self._poll_status()
            self._publish_tick_if_due()
            return
        reads = 0
        while tracker.wire.pump(0.01 if reads == 0 else 0) and reads < MAX_READS:  # what the link holds, bounded
            reads += 1
        samples, images = self._take()
        now = time.monotonic()
        if samples:
            self._last_sample_at = now
            self._process(samples)
        elif now - self._last_sample_at > self.timeout:
            tracker.status()  # raises if the device is gone; else it is just slow
            self._last_sample_at = now
        for got in images:
            self._image(got)
        self._run_script(now)
        if now - self._last_status >= STATUS_EVERY_S:
            self._poll_status()
        self._publish_tick_if_due()

    def _take(self) -> tuple[list[Sample], list[ReceivedImage]]:
        """The samples and images received so far (the wire and the reader bound both)."""
        wire = self.tracker.wire
        if self.reader is None:
            samples = list(wire.samples)
            wire.samples.clear()
            images = list(wire.images)
            wire.images.clear()
        else:
            self.live.add_truth(list(wire.samples))
            wire.samples.clear()
            samples, images = [], []
            while True:
                try:
                    samples.append(self.reader.read_sample(0))
                except TrackerTimeoutError:
                    break
                images.extend(self.reader.last_images)
        return samples, images

    def _process(self, samples: list[Sample]) -> None:
        screen = None if self.geometry is None else self.geometry.screen
        self.live.add(samples, estimate_gaze(samples, self.result, screen), self.sync)

    def _image(self, got: ReceivedImage) -> None:
        shown = self.live.image(got)
        if shown is not None:
            self.publish(shown[0])
            if self.recorder is not None:
                self.recorder.image(got.image, shown[1])

    def _run_script(self, now: float) -> None:
        if self.script is None:
            return
        target = self.script.target_at(now - self._script_t0)
        if target != self._target:
            self._target_id = (self._target_id + 1) % 256
            self.tracker.stimulus(self._target_id, *target)

    def _poll_status(self) -> None:
        status = self.tracker.status()
        self.device_status = {"samples_dropped": status.samples_dropped, "frames_dropped": status.frames_dropped,
                               "samples_sent": status.samples_sent, "frames_sent": status.frames_sent}
        self._last_status = time.monotonic()

    # --- publishing ---------------------------------------------------------------------------
    def _publish_tick_if_due(self) -> None:
        now = time.monotonic()
        if now - self._last_tick < self.tick_s:
            return
        self._last_tick = now
        host = self.tracker.stats if self.tracker is not None else None
        message = self.live.tick(host, {**self.device_status, **self.counters}, self._target)
        self.publish(message)
        if self.recorder is not None:
            self.recorder.tick(message)

    def _publish_hello(self) -> None:
        screen = None if self.geometry is None else self.geometry.screen
        self.publish(hello_message(self.tracker.info, self.url, self._mode(), screen, blink=self.oracle is not None))

    def _publish_state(self) -> None:
        tracker = self.tracker
        self.publish({"type": "state", "connected": tracker is not None,
                      "streaming": bool(tracker is not None and tracker.streaming), "calibrating": self.calibrating,
                      "error": self.error, "url": self.url,
                      "script": None if self.script is None else self.script.name})
