"""Shared machinery of the file-descriptor links (pseudo-terminal, TCP): a reader and a writer thread per link.

The reader selects on the link's readable descriptors and a wake-up pipe and hands received bytes to the
runner. `send` writes at once what the descriptor takes without waiting (`_send_now`, where the link can; the
common case on TCP: one system call on the runner's thread, no thread hop), queues the rest (at most
`MAX_LINK_BACKLOG` bytes; beyond, output is dropped and counted, ``bytes_dropped``; the device's own limits
normally keep far below it) and wakes the writer, which takes up to `WRITE_PIECE` bytes of the queue at a time and
writes each piece with one blocking call (`_transmit`). The interpreter lock is released for the whole of that call,
however many times the kernel waits for the host to read: a pseudo-terminal holds only about 12 kB, so a
non-blocking writer woke, and waited for the lock, some twenty times per 320 x 240 image. `backlog` counts the bytes
queued and those of the piece being written (so it falls piece by piece as the host reads, and the device's own
limits, which keep FEATURES ahead of images, see the link drain).

Subclasses fill five hooks: `_read_fds`, `_write_fd` (None while no host is attached: output is discarded),
`_readable(fd)`, `_transmit(data)` (a blocking write of all of `data` to the current host; OSError if it is
gone) and `_release`; `_unblock` must make a `_transmit` in progress return (the link is closing), and
`_send_now(data)` may write what the host takes without waiting.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
from collections.abc import Callable

from eyehil.emulator.device.links.base import register_open, unregister

CHUNK = 65536
MAX_LINK_BACKLOG = 4 * 1024 * 1024  # bytes queued for a host that does not read
WRITE_PIECE = 32 * 1024  # bytes the writer hands the kernel in one blocking call
UNBLOCK_POLL_S = 0.01  # closing: how often `_unblock` is tried again while the writer is still in `_transmit`


class FdLink:
    """Base of descriptor links; see the module docstring. Implements `DeviceLink` except `url`."""

    name = "fd link"
    url = ""

    def __init__(self) -> None:
        """Create the wake-up pipe and register the link as open."""
        self._out = bytearray()
        self._writing = 0  # bytes the writer took and is transmitting
        self._lock = threading.Lock()
        self._queued = threading.Condition(self._lock)
        self._wake_r, self._wake_w = os.pipe()
        for fd in (self._wake_r, self._wake_w):
            os.set_blocking(fd, False)
        self._receive: Callable[[bytes], None] = lambda data: None
        self._reset: Callable[[], None] = lambda: None
        self._threads: list[threading.Thread] = []
        self._closing = False
        self.bytes_dropped = 0
        register_open(self, self.name)

    # --- hooks -------------------------------------------------------------------------------
    def _read_fds(self) -> list[int]:
        """Descriptors to watch for input."""
        raise NotImplementedError

    def _write_fd(self) -> int | None:
        """Descriptor output goes to, or None when no host is attached (output is discarded)."""
        raise NotImplementedError

    def _readable(self, fd: int) -> None:
        """`fd` is readable: read it and call `self._receive` (or accept a connection ...)."""
        raise NotImplementedError

    def _transmit(self, data: bytes) -> None:
        """Write all of `data` to the current host, blocking (the writer's thread); OSError if it is gone."""
        raise NotImplementedError

    def _unblock(self) -> None:
        """Make a `_transmit` in progress return: the link is closing."""

    def _send_now(self, data: bytes) -> int:
        """Write what the host takes of `data` without waiting; return how many bytes (all if the host is gone)."""
        return 0

    def _release(self) -> None:
        """Close the subclass's descriptors."""
        raise NotImplementedError

    # --- DeviceLink ----------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._write_fd() is not None

    def attach(self, receive: Callable[[bytes], None], reset: Callable[[], None]) -> None:
        """Start the reader and writer threads."""
        self._receive, self._reset = receive, reset
        self._threads = [threading.Thread(target=self._read_loop, name=f"eyehil-{self.name}", daemon=True),
                         threading.Thread(target=self._write_loop, name=f"eyehil-{self.name} writer", daemon=True)]
        for thread in self._threads:
            thread.start()

    def send(self, data: bytes) -> None:
        """Write what the host takes at once (`_send_now`, when nothing waits before it), queue the rest for the writer;
        discard it if no host is attached, or what does not fit the queue (counted in `bytes_dropped`)."""
        if not data:
            return
        with self._lock:
            if self._write_fd() is None:
                return
            if not self._out and not self._writing:
                data = data[self._send_now(data):]
                if not data:
                    return
            if len(self._out) + len(data) > MAX_LINK_BACKLOG:
                self.bytes_dropped += len(data)
                return
            self._out += data
            self._queued.notify()

    def backlog(self) -> int:
        return len(self._out) + self._writing

    def close(self) -> None:
        """Stop the threads and close every descriptor; idempotent."""
        if self._closing:
            return
        with self._lock:
            self._closing = True
            self._queued.notify()
        self._poke()
        for thread in self._threads:
            if thread is threading.current_thread():
                continue
            while thread.is_alive():
                self._unblock()
                thread.join(UNBLOCK_POLL_S)
        with self._lock:
            self._release()
            self._out.clear()
        for fd in (self._wake_r, self._wake_w):
            os.close(fd)
        unregister(self)

    # --- internals -----------------------------------------------------------------------------
    def _poke(self) -> None:
        """Wake the reader."""
        with contextlib.suppress(OSError):  # the pipe is full: the thread is awake anyway
            os.write(self._wake_w, b"x")

    def _read_loop(self) -> None:
        while not self._closing:
            readable, _, _ = select.select([self._wake_r, *self._read_fds()], [], [], 1.0)
            if self._wake_r in readable:
                os.read(self._wake_r, CHUNK)
            for fd in readable:
                if fd != self._wake_r and not self._closing:
                    self._readable(fd)

    def _write_loop(self) -> None:
        while True:
            with self._queued:
                while not self._closing and not self._out:
                    self._queued.wait()
                if self._closing:
                    return
                data = bytes(self._out[:WRITE_PIECE])
                del self._out[:WRITE_PIECE]
                self._writing = len(data)
            try:
                self._transmit(data)
            except OSError:  # the host went away (or the link is closing): these bytes are lost, as on a cable
                pass
            finally:
                with self._lock:
                    self._writing = 0
