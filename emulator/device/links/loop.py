"""The loop link: a serial-like port whose other end is an in-process device (no threads, no descriptors).

What pyserial's ``loop://`` is to a serial port, `LoopPort` is to the virtual tracker: host code opens
``loop://?scene=guestrin2006&clock=fast`` (options: `eyehil.emulator.device.build.options_from_query`) and
talks bytes to a device living in the same process. The device runs on the caller's thread: each
`read` first lets it emit what is due. With the fast clock the device produces samples only when the
host reads (lockstep: no backlog, as fast as the host consumes); with the real clock `read` waits for
the next sample's due time, within its timeout.

This is the device end of a link like `pty_link` or `tcp_link`; drivers reach it only through the
loop:// entry of their scheme table (a lazy import by name), and see nothing but bytes.
"""

from __future__ import annotations

import threading
import time

from eyehil.emulator.device.build import DeviceOptions, build_device, options_from_query
from eyehil.emulator.device.links.base import FAST_BLOCK, FAST_LOW_WATER, register_open, unregister


class LoopPort:
    """pyserial-like: `read(size)` with `timeout` (s, None = block), `write`, `in_waiting`, `close`."""

    def __init__(self, core, timeout: float | None = 1.0, name: str = "loop://") -> None:
        """Wrap a device core (`VirtualTracker` or `IscanTracker`)."""
        self.core, self.timeout, self.name = core, timeout, name
        self._buf = bytearray()
        self._idle = threading.Event()  # never set: a cancellable wait for the device's next due time
        self.is_open = True
        register_open(self, name)

    def _service(self, want: int) -> None:
        """Let the device emit what is due; with the fast clock, also up to `FAST_LOW_WATER` bytes more while
        fewer than `want` are buffered (lockstep: the device runs only as far ahead as the host reads).

        Bytes in this port's buffer count as delivered (like a terminal's buffer): a host that does not
        read for long makes the device drop samples only through the device's own output limit.
        """
        clock = self.core.clock
        self.core.poll()
        self._buf += self.core.read_available()
        produced = 0
        while clock.fast and len(self._buf) < want and produced < FAST_LOW_WATER:
            due = self.core.next_due_us(FAST_BLOCK)
            if due is None:
                break
            clock.push(due)
            if not self.core.poll(due):
                break
            data = self.core.read_available()
            self._buf += data
            produced += len(data)

    @property
    def in_waiting(self) -> int:
        """Bytes readable without waiting."""
        self._check_open()
        self._service(1)
        return len(self._buf)

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes: returns when `size` are there or the timeout expires."""
        self._check_open()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while True:
            self._service(size)
            if len(self._buf) >= size:
                break
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            due = self.core.next_due_us()
            wait = 0.05 if due is None else self.core.clock.wall_delay_s(due)
            self._idle.wait(wait if remaining is None else min(wait, remaining))
        data = bytes(self._buf[:size])
        del self._buf[:size]
        return data

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Deliver bytes to the device at once."""
        self._check_open()
        self.core.feed(bytes(data))
        return len(data)

    def flush(self) -> None:
        """Nothing is buffered on the way to the device."""

    def reset_input_buffer(self) -> None:
        """Discard bytes the device sent that were not read yet."""
        self._buf.clear()
        self.core.read_available()

    def close(self) -> None:
        """Release the device; idempotent."""
        if self.is_open:
            self.is_open = False
            self.core.close()
            unregister(self)

    def _check_open(self) -> None:
        if not self.is_open:
            raise OSError("loop port is closed")

    def __enter__(self) -> LoopPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_loop(url: str, timeout: float | None = 1.0, base: DeviceOptions | None = None) -> LoopPort:
    """A `LoopPort` for ``loop://?key=value&...`` (the query gives `DeviceOptions`)."""
    if not url.startswith("loop://"):
        raise ValueError(f"not a loop:// URL: {url!r}")
    query = url[len("loop://"):].lstrip("/").removeprefix("?")
    options = options_from_query(query, base)
    if options.link_rate:
        raise ValueError("link_rate paces the native links (pty, tcp, usbip), not loop://")
    return LoopPort(build_device(options), timeout, name=url)
