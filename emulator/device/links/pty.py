"""Device side of a pseudo-terminal link: the host opens `url` (e.g. /dev/pts/5) like a serial port.

`os.openpty` gives a master (the device's end) and a slave (the serial port the host opens); the slave
is put in raw mode (`tty.setraw`: no echo, no line discipline, 8-bit clean) and kept open by the device
for the link's lifetime, so the path stays valid while hosts come and go. The master is blocking: the writer
thread hands the kernel all queued output in one `write`, which returns when the host has taken it (the
terminal holds about 12 kB); the reader reads it only when `select` says it is readable. The device cannot tell
whether a host has the port open: output written while nobody reads fills the terminal's buffer, then
the link's queue, and the device then drops samples (STATUS `samples_dropped`); a host should discard
stale input when it opens the port (pyserial: `reset_input_buffer`). Baud rate and framing settings
are accepted and ignored, as on a USB CDC-ACM port.
"""

from __future__ import annotations

import contextlib
import os
import tty

from eyehil.emulator.device.links.fdlink import CHUNK, FdLink


class PtyLink(FdLink):
    """A pseudo-terminal; `url` is the slave's path."""

    def __init__(self) -> None:
        """Open the pseudo-terminal pair."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._slave, False)  # the device's own end of the slave is read only to unblock a close
        self.url = os.ttyname(self._slave)
        self.name = f"pty {self.url}"
        super().__init__()

    def _read_fds(self) -> list[int]:
        return [self._master]

    def _write_fd(self) -> int | None:
        return None if self._closing else self._master

    def _readable(self, fd: int) -> None:
        try:
            data = os.read(fd, CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:  # EIO: no slave open (cannot happen while the device holds the slave)
            return
        if data:
            self._receive(data)

    def _transmit(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self._master, view):]

    def _unblock(self) -> None:
        with contextlib.suppress(OSError):  # nothing to read (BlockingIOError): the writer is not stuck on it
            while os.read(self._slave, CHUNK):
                pass

    def _release(self) -> None:
        os.close(self._master)
        os.close(self._slave)
