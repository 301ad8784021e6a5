"""The device side of links: the two interfaces a transport module implements, and the runner joining them.

A link is one small module (`pty_link.py`, `tcp_link.py`, `usbip_link.py` over `usbip_server.py` ...)
implementing `DeviceLink`; `LinkRunner` puts any `DeviceCore` on any `DeviceLink`:

    core = build_device(DeviceOptions(scene="guestrin2006"))      # VirtualTracker or IscanTracker
    with LinkRunner(core, PtyLink()) as runner:
        print(runner.url)                                          # what a host opens

DeviceLink (a byte pipe to at most one host at a time; the link owns its threads and buffers)::

    name: str                     short description for logs, e.g. "pty /dev/pts/5"
    url: str                      what a host passes to drivers' open_tracker (a path, socket://h:p, usbip://h:p)
    connected: bool               a host is attached (TCP client present, USB device imported); links that
                                  cannot tell (pty) say True
    attach(receive, reset)        start the I/O; from then on call receive(data: bytes) for every chunk the
                                  host sends (from the link's own thread) and reset() when a NEW host
                                  connects (a new byte stream: the device forgets a partial frame)
    send(data: bytes) -> None     queue bytes for the host; never blocks; discards them if no host is attached
    backlog() -> int              bytes queued in the link, not yet taken by the transport (kernel, USB)
    close() -> None               stop the link's threads and release every fd/socket; idempotent

A link registers itself with `register_open(self, name)` when it acquires resources and
`unregister(self)` when closed, so that tests can assert that nothing leaked (`open_links()`); the
tests/device leak check also fails on threads named "eyehil..." and on sockets, pipes and
pseudo-terminals left open. A new link is added to `eyehil.emulator.device.cli.LINKS` (``--link NAME``; its
class is called with ``host=``, ``port=`` keywords) and to tests/device/device_helpers.LINK_CLASSES
(the suite then runs against it). A byte pipe with a receive callback and a `send` (such as
`usbip_server.UsbipCdcServer`) needs only an adapter: `attach` stores `receive` and starts the pipe,
`connected` / `backlog` / `send` / `close` forward to it.

DeviceCore (bytes in, bytes out; `VirtualTracker`, `IscanTracker`; not thread-safe: only the runner's
thread calls it)::

    clock                         the device clock (`eyehil.emulator.device.clock`)
    feed(data)                    bytes from the host
    poll(now_us=None, backlog=0)  queue the samples due; drop (and count) those that would exceed the
                                  core's output limit given `backlog` bytes already queued downstream
    read_available(max_bytes=None) -> bytes;  pending -> int
    next_due_us(count=1, wake=True) -> int | None   device time by which the next `count` samples are due
                                  (`wake`: or sooner, when the core wants an early look)
    fast_room(backlog) -> bool    optional: fast clock, may the next samples be taken now (default: the
                                  link holds less than `FAST_LOW_WATER`); set_wake(callable) optional
    connection_reset();  close()

The runner's thread owns the core: it wakes at each sample's due time (real clock), whenever the link
has room (fast clock: it pushes device time one block of samples at a time while the link has room,
`fast_room`, so a device in lockstep with its host never drops a sample for a slow host) and whenever the link
received bytes, which it feeds and answers at once. A link with `pump()` and `wake_delay_s()`
(`paced.PacedLink`, the link-rate option) is also pumped at each wake-up and wakes the runner when it can take
more.

Limits (a host that floods commands and never reads cannot grow the device): the runner's inbox holds at
most `MAX_INBOX_BYTES` / `MAX_INBOX_CHUNKS`; bytes beyond are dropped and counted (`counters`
``input_dropped_bytes``, ``input_dropped_chunks``). While the link holds `MAX_REPLY_BACKLOG` bytes or
more that the host did not take, the runner stops feeding the core (its replies would only pile up), so
the inbox fills and the host's further input is dropped: the device keeps its memory and its stream.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import Protocol

_OPEN: dict[int, str] = {}
_OPEN_LOCK = threading.Lock()
FAST_LOW_WATER = 8192  # fast clock: produce more samples only while the link holds less than this (bytes), unless
# the core says otherwise (`fast_room`: a frame stream's own bounded render-ahead queue and frame budget)
FAST_BLOCK = 32  # fast clock: samples produced per step
FAST_STEPS = 4  # fast clock: steps between two looks at the host's commands
IDLE_WAIT_S = 0.25
PACED_MIN_WAIT_S = 0.0002  # a paced link's runner sleeps at least this long between hand-overs (wall s)
MAX_INBOX_BYTES = 256 * 1024  # host bytes waiting for the runner
MAX_INBOX_CHUNKS = 4096  # host reads waiting for the runner
MAX_REPLY_BACKLOG = 1024 * 1024  # link backlog (bytes) above which the runner stops feeding commands (> the
# device's own sample and frame limits, so a streaming device always takes commands)


def take(buffer: bytearray, max_bytes: int | None = None) -> bytes:
    """Remove and return up to `max_bytes` (default all) bytes from the front of a core's output buffer."""
    n = len(buffer) if max_bytes is None else min(max_bytes, len(buffer))
    if n == len(buffer):  # all of it (the usual case): one copy
        data = bytes(buffer)
        buffer.clear()
        return data
    with memoryview(buffer) as view:
        data = bytes(view[:n])
    del buffer[:n]
    return data


def register_open(link: object, name: str) -> None:
    """Record that `link` holds resources (file descriptors, sockets, threads)."""
    with _OPEN_LOCK:
        _OPEN[id(link)] = name


def unregister(link: object) -> None:
    """Record that `link` released its resources."""
    with _OPEN_LOCK:
        _OPEN.pop(id(link), None)


def open_links() -> list[str]:
    """Names of the links not closed yet (for leak checks)."""
    with _OPEN_LOCK:
        return sorted(_OPEN.values())


class DeviceLink(Protocol):
    """See the module docstring."""

    name: str
    url: str

    @property
    def connected(self) -> bool: ...

    def attach(self, receive: Callable[[bytes], None], reset: Callable[[], None]) -> None: ...

    def send(self, data: bytes) -> None: ...

    def backlog(self) -> int: ...

    def close(self) -> None: ...


class LinkRunner:
    """Runs one device core on one link; a context manager.

    One thread ("eyehil-runner ...") owns the core: bytes the link receives are queued (`_inbox`) and
    fed by that thread, so no lock is held across the core and a busy stream never starves commands.
    """

    def __init__(self, core, link: DeviceLink) -> None:
        """Join `core` (a DeviceCore) and `link`; call `start` (or use `with`)."""
        self.core, self.link = core, link
        self._inbox: deque[bytes | None] = deque()  # None: a new host connected
        self._inbox_bytes = 0
        self._inbox_lock = threading.Lock()
        self.counters = {"input_dropped_bytes": 0, "input_dropped_chunks": 0, "resets": 0}
        self._wake = threading.Event()
        self._stopping = False
        self.failure: Exception | None = None  # what stopped the thread, if it died
        self._thread = threading.Thread(target=self._run, name=f"eyehil-runner {link.name}", daemon=True)

    @property
    def url(self) -> str:
        """What a host opens."""
        return self.link.url

    def start(self) -> LinkRunner:
        """Attach to the link and start the thread."""
        self.link.attach(self._receive, self._reset)
        if hasattr(self.core, "set_wake"):
            self.core.set_wake(self._wake.set)
        self._thread.start()
        return self

    def __enter__(self) -> LinkRunner:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _receive(self, data: bytes) -> None:
        """Called by the link's thread: queue the bytes for the runner (dropped, counted, beyond the limits)."""
        with self._inbox_lock:
            if self._inbox_bytes + len(data) > MAX_INBOX_BYTES or len(self._inbox) >= MAX_INBOX_CHUNKS:
                self.counters["input_dropped_bytes"] += len(data)
                self.counters["input_dropped_chunks"] += 1
                return
            self._inbox.append(bytes(data))
            self._inbox_bytes += len(data)
        self._wake.set()

    def _reset(self) -> None:
        """A new host: whatever the previous one sent and the device did not read yet is forgotten."""
        with self._inbox_lock:
            self._inbox.clear()
            self._inbox_bytes = 0
            self._inbox.append(None)
            self.counters["resets"] += 1
        self._wake.set()

    @property
    def inbox_bytes(self) -> int:
        """Host bytes waiting for the runner."""
        return self._inbox_bytes

    def _drain_inbox(self) -> None:
        """Feed what the host sent and send the responses at once (not while the host leaves replies unread)."""
        while self._inbox and self.link.backlog() < MAX_REPLY_BACKLOG:
            with self._inbox_lock:
                data = self._inbox.popleft()
                self._inbox_bytes -= len(data) if data is not None else 0
            if data is None:
                self.core.connection_reset()
            else:
                self.core.feed(data)
        self._flush()

    def _flush(self) -> None:
        data = self.core.read_available()
        if data:
            self.link.send(data)

    def _service(self) -> float:
        """Emit what is due; return how long (wall seconds) the thread may wait."""
        clock = self.core.clock
        self.core.poll(backlog=self.link.backlog())
        self._flush()
        if clock.fast and self.link.connected:
            for _ in range(FAST_STEPS):
                due = self.core.next_due_us(FAST_BLOCK, wake=False)
                if due is None or not self._fast_room():
                    break
                clock.push(due)
                self.core.poll(due, self.link.backlog())
                self._flush()
            idle = self.core.next_due_us() is None
            return IDLE_WAIT_S if idle else (0.0 if self._fast_room() else 0.001)
        if clock.fast:  # no host to pace a fast clock: wait for one (a connecting host wakes the thread)
            return IDLE_WAIT_S
        due = self.core.next_due_us()
        return IDLE_WAIT_S if due is None else min(IDLE_WAIT_S, clock.wall_delay_s(due))

    def _pace(self, wait: float) -> float:
        """A paced link (`paced.PacedLink`): hand it what its rate admits now; wake when it admits more."""
        pump = getattr(self.link, "pump", None)
        if pump is None:
            return wait
        pump()
        delay = self.link.wake_delay_s()
        return wait if delay is None else min(wait, max(delay, PACED_MIN_WAIT_S))

    def _fast_room(self) -> bool:
        """Fast clock: may the device take its next samples? The core decides if it can (`fast_room`: a frame
        stream renders ahead into a bounded queue); otherwise while the link holds less than `FAST_LOW_WATER`."""
        backlog = self.link.backlog()
        room = getattr(self.core, "fast_room", None)
        return room(backlog) if room is not None else backlog < FAST_LOW_WATER

    def _run(self) -> None:
        try:
            while not self._stopping:
                self._wake.clear()
                self._drain_inbox()
                wait = self._pace(self._service())
                if wait > 0:
                    self._wake.wait(wait)
        except Exception as exc:  # a bug in a core or link: the device stops, loudly, instead of hanging
            self.failure = exc
            logging.getLogger(__name__).exception("device runner on %s stopped", self.link.name)

    def close(self) -> None:
        """Stop the thread, close the link and the core; idempotent."""
        self._stopping = True
        self._wake.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join()
        self.link.close()
        self.core.close()
