"""The camera behind the C firmware's host HAL: a simulated subject's features or raw frames, one text line per
request.

`firmware_stubs/hal_sensor.c` (the host build of the reference firmware) asks this process for the detected
features of each camera exposure (a camera with a hardware detector, ``--camera features``) or for its raw
8-bit pixels (``--camera pixels``: the firmware extracts the features itself), and forwards the host's
STIMULUS messages to it. The firmware owns the clock
(every time here is its device time, us), the exposure schedule and the frame ids; this side is the optics
and the detector: `Subject.observe` (exact ray-traced fixations, interpolated movements) then `camera.detect`
(flags, region of interest, LEDs), the code the Python `VirtualTracker` streams from, so the C firmware sends
the same values, rounded once to float32. Raw frames are drawn by the project's renderer
(`frames.render_region`: the ray-traced outline, blur, read and shot noise, saturation) into the window the
firmware asks for, showing every eye the camera sees; during a blink each eye is drawn with its lids shut
over its last open pose (as the device's FRAMES do); a glint is drawn only for an LED lit in that exposure
(the unlit LEDs' glint channels are blanked before drawing). The noise generator of the frame at t_us is
``default_rng([seed, t_us])``. The ground truth of the last `TRUTH_KEPT` frames is kept (`truth_at`) for
scoring. Image px (OpenCV convention), degrees, screen mm as on the wire.

Line protocol (ASCII; the firmware sends one request line, this side answers one line; fields separated by one
space; floats printed with `repr`, which reads back to the same float64). Full table: firmware_stubs/README.md.

    HELLO 1                                   -> INFO <width_px> <height_px> <led_count> <eyes> <stimulus>
    LEDS <count>                              -> OK
    START <rate_hz> <eyes> <roi_x> <roi_y> <roi_w> <roi_h>    -> OK
    STOP                                      -> OK
    EXPOSE <t_us>                             -> FEATURES <n_eyes> then per eye: <eye> <flags> <cx> <cy> <a> <b>
                                                 <angle_deg> <confidence> <n_glints>, then per glint: <led>
                                                 <flags> <x> <y>
    STIMULUS <t_us> <target_id> <x_mm> <y_mm> <flags>         -> OK, or ERR <reason> (position refused)
    GEOMETRY                                  -> GEOMETRY <right_eye_low_x> <led_count> then per LED:
                                                 <dir_x> <dir_y> (its image direction from the lens)
    FRAME <t_us> <exposure_us> <led_mask> <x> <y> <w> <h>     -> PIXELS <w> <h>, then exactly w * h bytes
                                                 (row-major, 8-bit) of the sensor window at (x, y)
    anything else                             -> ERR <reason>

`FirmwareSensor` is the protocol without I/O; `SensorServer` serves it on a Unix socket to one firmware at a
time, on one thread named "eyehil-sensor ..."; ``python -m eyehil.emulator.device.firmware_sensor --socket PATH``
runs one until interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import selectors
import signal
import socket
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver, closed
from eyehil.emulator.device.build import DeviceOptions, build_subject, options_from_query
from eyehil.emulator.device.camera import Selection, detect
from eyehil.emulator.device.frames import ExposureRenderer, render_region
from eyehil.emulator.device.links.base import register_open, unregister
from eyehil.emulator.device.stimulus import stimulus_problem, stimulus_to_screen
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.renderer import Frame, RenderSettings
from eyehil.protocols.enums import Eye, StimulusFlags
from eyehil.stopping import wait_for_stop

MAX_LINE = 4096  # bytes of one request line
TRUTH_KEPT = 4096  # frames whose ground truth `truth_at` still knows
DEFAULT_EXPOSURE_US = 1000  # the integration time at which the renderer's exposure 1.0 applies
MAX_FRAME_PX = 2048 * 1536  # largest window served (the firmware's static frame buffer)


def _ints(args: list[str], count: int) -> list[int]:
    """`count` decimal integers, or ValueError."""
    if len(args) != count:
        raise ValueError(f"expected {count} fields, got {len(args)}")
    return [int(a) for a in args]


def format_features(fields: dict[str, np.ndarray], eyes: tuple[Eye, ...], leds: int) -> str:
    """The FEATURES reply line of the first sample of `camera.detect` output (E eyes, `leds` glints each)."""
    parts = ["FEATURES", str(len(eyes))]
    for e, eye in enumerate(eyes):
        ellipse = (*fields["centre"][0, e], *fields["axes"][0, e], fields["angle_deg"][0, e],
                   fields["confidence"][0, e])
        parts += [str(int(eye)), str(int(fields["flags"][0, e])), *(repr(float(v)) for v in ellipse), str(leds)]
        for g in range(leds):
            xy = fields["glint_xy"][0, e, g]
            parts += [str(g), str(int(fields["glint_flags"][0, e, g])), repr(float(xy[0])), repr(float(xy[1]))]
    return " ".join(parts)


class FirmwareSensor:
    """Answers the firmware's request lines from a simulated subject; see the module docstring. Not thread-safe."""

    def __init__(self, subject: Subject, *, seed: int = 0, settings: RenderSettings | None = None) -> None:
        """The camera of `subject`'s scene (sensor size, LEDs, the eyes it sees) in front of `subject`; raw frames
        need its solver to be an `AppearanceSolver` (noise from `seed`, looks from `settings`)."""
        scene = subject.solver.scene
        self.subject, self.seed = subject, seed
        self.renderer = (ExposureRenderer.for_subject(subject, settings)
                         if isinstance(subject.solver, AppearanceSolver) else None)
        self.truths: deque[tuple[int, int, tuple[int, int, int, int], Frame]] = deque(maxlen=TRUTH_KEPT)
        self._open: dict[int, np.ndarray] = {}  # each tracked eye's last open row (drawn shut during blinks)
        self.sensor = tuple(int(v) for v in scene.camera.resolution_px)
        self.tracked = tuple(Eye.RIGHT if s == "right" else Eye.LEFT for s in scene.sides)
        self.led_count = len(scene.leds)
        self._pixels = b""
        self.leds = 0
        self._eyes: tuple[Eye, ...] | None = None  # selected at START; None while stopped
        self._roi: tuple[int, int, int, int] | None = None
        self.stimuli: list[tuple[int, int, float, float, int]] = []  # accepted: (t_us, target_id, x_mm, y_mm, flags)
        self._requests: dict[str, Callable[[list[str]], str]] = {
            "HELLO": self._hello, "LEDS": self._leds, "START": self._start, "STOP": self._stop,
            "EXPOSE": self._expose, "STIMULUS": self._stimulus, "GEOMETRY": self._geometry, "FRAME": self._frame}

    @classmethod
    def from_options(cls, options: DeviceOptions | None = None, *, frames: bool = False,
                     settings: RenderSettings | None = None) -> FirmwareSensor:
        """A sensor in front of the subject `options` describe (scene, eye, head, behaviour, script, seed; the
        device's rate, clock and mode are the firmware's business and are ignored); with `frames`, one that
        also serves raw frames (its subject then carries appearance channels, whose solver's features differ
        from the plain one's in the last bits: without `frames` the features equal the Python device's)."""
        options = options or DeviceOptions()
        return cls(build_subject(options, appearance=frames), seed=options.seed, settings=settings)

    def handle_bytes(self, line: str) -> bytes:
        """The reply (newline included, then the pixels for FRAME) to one request line."""
        reply = self.handle(line)
        pixels, self._pixels = self._pixels, b""
        return reply.encode("ascii") + b"\n" + (pixels if reply.startswith("PIXELS") else b"")

    def truth_at(self, t_us: int) -> tuple[int, tuple[int, int, int, int], Frame] | None:
        """(LED mask, window (x, y, w, h), frame with its ground truth) of the frame served for time `t_us`."""
        for t, mask, window, frame in reversed(self.truths):
            if t == t_us:
                return mask, window, frame
        return None

    def render(self, t_us: int, led_mask: int, window: tuple[int, int, int, int], exposure_us: int = 0) -> Frame:
        """The raw frame of the exposure whose mid-time is `t_us`: the sensor `window` (x, y, w, h), the LEDs of
        `led_mask` lit; its ground truth is kept (`truth_at`)."""
        if self.renderer is None:
            raise ValueError("this sensor serves no frames (its subject has no appearance channels)")
        x, y, w, h = window
        sw, sh = self.sensor
        if not (w > 0 and h > 0 and 0 <= x <= sw - w and 0 <= y <= sh - h and w * h <= MAX_FRAME_PX):
            raise ValueError(f"window {window} not on the {sw}x{sh} sensor")
        if not 0 <= led_mask < (1 << self.led_count):
            raise ValueError(f"LED mask {led_mask} for {self.led_count} LEDs")
        obs = self.subject.observe(np.array([t_us], dtype=np.int64))
        rows = np.stack([self._row(i, obs.values[0], bool(obs.blink[0])) for i in range(len(self.tracked))])
        first = self.renderer.layout.features - 2 * self.led_count  # the glint channels (x, y per LED)
        for led in range(self.led_count):
            if not led_mask >> led & 1:
                rows[:, first + 2 * led: first + 2 * led + 2] = np.nan  # an unlit LED makes no reflection
        renderer = self.renderer
        if exposure_us and exposure_us != DEFAULT_EXPOSURE_US:
            sensor = renderer.settings.sensor
            settings = replace(renderer.settings, sensor=replace(sensor, exposure=sensor.exposure * exposure_us
                                                                   / DEFAULT_EXPOSURE_US))
            renderer = replace(renderer, settings=settings)
        rng = np.random.default_rng([self.seed, int(t_us)])
        frame = render_region(renderer, rows, tuple(range(len(rows))), window, rng)
        self.truths.append((int(t_us), led_mask, window, frame))
        return frame

    def _row(self, i: int, values: np.ndarray, blink: bool) -> np.ndarray:
        """Channels to draw of tracked eye `i`: its own, or during a blink its last open row with the lids shut."""
        row = np.array(values[i], float)
        if not blink:
            self._open[i] = row
            return row
        last = self._open.get(i)
        return row if last is None else closed(last, self.renderer.layout)

    def handle(self, line: str) -> str:
        """The reply line (without newline) to one request line."""
        word, *args = line.split() or [""]
        request = self._requests.get(word)
        if request is None:
            return f"ERR unknown request {word[:20]!r}"
        try:
            return request(args)
        except ValueError as exc:
            return f"ERR {word}: {exc}"

    def features(self, times_us: np.ndarray) -> dict[str, np.ndarray]:
        """Detected features (`camera.detect` fields) of exposures at `times_us` (ascending) with the current
        selection and LEDs."""
        if self._eyes is None:
            raise ValueError("not started")
        obs = self.subject.observe(np.asarray(times_us, dtype=np.int64))
        return detect(obs.values, obs.blink, Selection(self._eyes, self.leds, self._roi), self.tracked, self.sensor)

    def close(self) -> None:
        """Release the subject's worker thread."""
        self.subject.close()

    # --- requests ---------------------------------------------------------------------------------------------
    def _hello(self, args: list[str]) -> str:
        _ints(args, 1)
        self.leds, self._eyes = 0, None
        eyes = sum(1 << int(e) for e in self.tracked)
        return f"INFO {self.sensor[0]} {self.sensor[1]} {self.led_count} {eyes} 1"

    def _leds(self, args: list[str]) -> str:
        (count,) = _ints(args, 1)
        if not 0 <= count <= self.led_count:
            raise ValueError(f"{count} LEDs, the scene has {self.led_count}")
        self.leds = count
        return "OK"

    def _start(self, args: list[str]) -> str:
        rate, eyes, *roi = _ints(args, 6)
        if not (rate > 0 and 1 <= eyes <= 3):
            raise ValueError("rate or eyes out of range")
        self._eyes = tuple(e for e in (Eye.RIGHT, Eye.LEFT) if eyes & (1 << e))
        self._roi = (roi[0], roi[1], roi[2], roi[3]) if roi[2] else None
        return "OK"

    def _stop(self, args: list[str]) -> str:
        _ints(args, 0)
        self._eyes = None
        return "OK"

    def _expose(self, args: list[str]) -> str:
        (t_us,) = _ints(args, 1)
        return format_features(self.features(np.array([t_us])), self._eyes, self.leds)

    def _geometry(self, args: list[str]) -> str:
        _ints(args, 0)
        if self.renderer is None:
            raise ValueError("this sensor serves no frames")
        # The camera faces the subject: the right eye appears at smaller image x. Each LED's glint lies on its
        # side of the camera: image x follows scene x, image y follows scene -y (LED positions, mm).
        leds = np.asarray(self.subject.solver.scene.leds, float)[:, :2] * [1.0, -1.0]
        scale = max(float(np.abs(leds).max()), 1e-9)
        return " ".join(["GEOMETRY", "1", str(self.led_count), *(repr(float(v)) for v in (leds / scale).ravel())])

    def _frame(self, args: list[str]) -> str:
        t_us, exposure_us, mask, *window = _ints(args, 7)
        if not 0 <= exposure_us <= 1_000_000:
            raise ValueError("exposure out of range")
        frame = self.render(t_us, mask, (window[0], window[1], window[2], window[3]), exposure_us)
        self._pixels = np.ascontiguousarray(frame.image, dtype=np.uint8).tobytes()
        return f"PIXELS {window[2]} {window[3]}"

    def _stimulus(self, args: list[str]) -> str:
        if len(args) != 5:
            raise ValueError(f"expected 5 fields, got {len(args)}")
        t_us, target_id, flags = int(args[0]), int(args[1]), int(args[4])
        x_mm, y_mm = float(args[2]), float(args[3])
        screen = self.subject.solver.scene.screen
        problem = stimulus_problem(screen, x_mm, y_mm)
        if problem is not None:
            return f"ERR {problem}"
        if flags & StimulusFlags.VISIBLE:
            self.subject.look_at(stimulus_to_screen(screen, x_mm, y_mm), t_us)
        self.stimuli.append((t_us, target_id, x_mm, y_mm, flags))
        return "OK"


class SensorServer:
    """Serves a `FirmwareSensor` on a Unix stream socket at `path`, one firmware connection at a time (a new one
    replaces the old), on one thread; a context manager. It owns the sensor: `close` closes it too."""

    def __init__(self, sensor: FirmwareSensor, path: str | os.PathLike[str]) -> None:
        """Bind and listen at `path` (which must not exist); call `start` (or use `with`)."""
        self.sensor, self.path = sensor, os.fspath(path)
        self.failure: Exception | None = None  # what stopped the thread, if it died
        self.connections = 0
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._wake_r, self._wake_w = socket.socketpair()
        self._conn: socket.socket | None = None
        self._pending = b""
        try:
            self._listener.bind(self.path)
            self._listener.listen(1)
        except OSError:
            self._close_sockets()
            raise
        self._thread = threading.Thread(target=self._run, name=f"eyehil-sensor {self.path}", daemon=True)
        register_open(self, f"sensor {self.path}")

    def start(self) -> SensorServer:
        self._thread.start()
        return self

    def __enter__(self) -> SensorServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        try:
            with selectors.DefaultSelector() as selector:
                selector.register(self._listener, selectors.EVENT_READ)
                selector.register(self._wake_r, selectors.EVENT_READ)
                while self._serve_once(selector):
                    pass
        except Exception as exc:  # a bug: the connection closes (the firmware then stops) instead of hanging
            self.failure = exc
            logging.getLogger(__name__).exception("firmware sensor on %s stopped", self.path)
        finally:
            self._drop(None)

    def _serve_once(self, selector: selectors.BaseSelector) -> bool:
        """Handle what is ready; False when asked to stop."""
        for key, _ in selector.select():
            if key.fileobj is self._wake_r:
                return False
            if key.fileobj is self._listener:
                self._drop(selector)
                self._conn, _ = self._listener.accept()
                self.connections += 1
                selector.register(self._conn, selectors.EVENT_READ)
            elif key.fileobj is self._conn and not self._answer(self._conn.recv(65536)):
                self._drop(selector)
        return True

    def _answer(self, data: bytes) -> bool:
        """Answer every complete request line in `data`; False when the firmware has gone (or sent garbage)."""
        self._pending += data
        while (end := self._pending.find(b"\n")) >= 0:
            line, self._pending = self._pending[:end], self._pending[end + 1 :]
            self._conn.sendall(self.sensor.handle_bytes(line.decode("ascii", errors="replace")))
        return bool(data) and len(self._pending) <= MAX_LINE

    def _drop(self, selector: selectors.BaseSelector | None) -> None:
        """Close the firmware connection, if any."""
        if self._conn is not None:
            if selector is not None:
                selector.unregister(self._conn)
            self._conn.close()
        self._conn, self._pending = None, b""

    def _close_sockets(self) -> None:
        for s in (self._listener, self._wake_r, self._wake_w):
            s.close()

    def close(self) -> None:
        """Stop the thread, close every socket, remove the socket file, close the sensor; idempotent."""
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        if self._thread.is_alive():
            self._thread.join()
        self._close_sockets()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)
        self.sensor.close()
        unregister(self)


def main(argv: list[str] | None = None) -> int:
    """``python -m eyehil.emulator.device.firmware_sensor --socket PATH [--scene S] [--options QUERY] [--frames]``."""
    parser = argparse.ArgumentParser(prog="python -m eyehil.emulator.device.firmware_sensor", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--socket", required=True, help="Unix socket path to listen on (the firmware's --sensor)")
    parser.add_argument("--scene", default="guestrin2006", help="scene preset or TOML path")
    parser.add_argument("--options", default="", help="more device options, e.g. 'eyes=published&eye=17&script=demo'")
    parser.add_argument("--frames", action="store_true", help="also serve raw frames (the firmware's --camera pixels)")
    args = parser.parse_args(argv)
    options = options_from_query(args.options, DeviceOptions(scene=args.scene))
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with SensorServer(FirmwareSensor.from_options(options, frames=args.frames), args.socket) as server:
            print(f"sensor: {server.path}", flush=True)
            with contextlib.suppress(KeyboardInterrupt):
                wait_for_stop(stop)  # in slices: the signal may land on another thread
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
