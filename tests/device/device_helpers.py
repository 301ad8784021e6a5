"""Helpers of the device/host tests: start an emulator on a backend, transports that lose or corrupt frames."""

from __future__ import annotations

import threading
from collections.abc import Callable
from urllib.parse import urlencode

from eyehil.emulator.device.build import DeviceOptions, build_device, options_from_query
from eyehil.emulator.device.links.base import LinkRunner
from eyehil.protocols.native import DEVICE_TYPES, Message, encode
from eyehil.protocols.stream import NativeReceiver, Received

LINK_CLASSES = {"pty": "eyehil.emulator.device.links.pty:PtyLink", "tcp": "eyehil.emulator.device.links.tcp:TcpLink",
                "usbip": "eyehil.emulator.device.links.usbip.link:UsbipLink"}


def query(**options: object) -> str:
    """``key=value&...`` with the fast clock unless told otherwise."""
    return urlencode({"clock": "fast", **options})


def start_emulator(backend: str, **options: object) -> tuple[str, Callable[[], None]]:
    """(URL, close) of a fresh emulator on `backend` ("loop", "pty", "tcp")."""
    if backend == "loop":
        return f"loop://?{query(**options)}", lambda: None
    module, cls = LINK_CLASSES[backend].split(":")
    link_class = getattr(__import__(module, fromlist=[cls]), cls)
    runner = LinkRunner(build_device(options_from_query(query(**options))), link_class()).start()
    return runner.url, runner.close


class FrameFilter:
    """A SerialLike wrapper that edits the device -> host stream frame by frame (whole frames, delimiter included).

    `decide(index, frame) -> bytes` returns what to deliver for the index-th frame (the frame itself, b""
    to drop it, or altered bytes); `delivered` and `edited` record what happened.
    """

    def __init__(self, inner, decide: Callable[[int, bytes], bytes]) -> None:
        self.inner, self.decide = inner, decide
        self._partial = bytearray()
        self._ready = bytearray()
        self.index = 0
        self.edited: list[int] = []
        if hasattr(inner, "fileno"):
            self.fileno = inner.fileno

    @property
    def timeout(self):
        return self.inner.timeout

    @timeout.setter
    def timeout(self, value) -> None:
        self.inner.timeout = value

    def read(self, size: int = 1) -> bytes:
        self._partial += self.inner.read(max(size, 4096))
        while (end := self._partial.find(0)) >= 0:
            frame = bytes(self._partial[: end + 1])
            del self._partial[: end + 1]
            out = self.decide(self.index, frame)
            if out != frame:
                self.edited.append(self.index)
            self._ready += out
            self.index += 1
        data = bytes(self._ready[:size])
        del self._ready[:size]
        return data

    def write(self, data: bytes) -> int | None:
        return self.inner.write(data)

    def reset_input_buffer(self) -> None:
        if hasattr(self.inner, "reset_input_buffer"):
            self.inner.reset_input_buffer()

    def close(self) -> None:
        self.inner.close()


class DeadLink:
    """A SerialLike that accepts writes and never delivers a byte (a device that is off); reads block for
    their timeout, as a real port's would."""

    def __init__(self) -> None:
        self.timeout = 0.0
        self.written = bytearray()
        self.closed = False
        self.waited_s = 0.0  # the reads' timeouts added up: how long the host chose to wait in all
        self._never = threading.Event()

    def read(self, size: int = 1) -> bytes:
        if self.timeout:
            self.waited_s += self.timeout
            self._never.wait(self.timeout)
        return b""

    def write(self, data: bytes) -> int:
        self.written += data
        return len(data)

    def close(self) -> None:
        self.closed = True


class ManualClock:
    """A device clock the test sets by hand (microseconds)."""

    fast = False

    def __init__(self, now_us: int = 0) -> None:
        self.now = now_us

    def now_us(self) -> int:
        return self.now

    def push(self, t_us: int) -> None:
        """Not a fast clock: ignored."""

    def wall_delay_s(self, t_us: int) -> float:
        return 0.0


class CoreHost:
    """Drives a device core with bytes: numbered commands in, decoded device messages out."""

    def __init__(self, core) -> None:
        self.core = core
        self.receiver = NativeReceiver(accept=DEVICE_TYPES)
        self.seq = 100

    def send(self, message: Message) -> int:
        """Feed one command; return its sequence number."""
        self.seq += 1
        self.core.feed(encode(message, self.seq, 5_000))
        return self.seq

    def read(self) -> list[Received]:
        """Every message the device queued, decoded (faults would fail the test)."""
        events = self.receiver.feed(self.core.read_available())
        assert all(isinstance(e, Received) for e in events), events
        return events

    def messages(self) -> list:
        return [e.message for e in self.read()]


def core_device(clock=None, **options: object):
    """A native device core with a manual clock (time 0) for byte-level tests."""
    core = build_device(options_from_query(query(**options), DeviceOptions()))
    core.clock = clock or ManualClock()
    return core
