"""One host attached to the virtual CDC-ACM device over USB/IP: the URB phase of a connection.

Two threads per session. The *reader* (the connection's thread, in `run`) decodes URBs: control
transfers go to `CdcAcmControl`, bulk OUT data to the `on_data` callback (called in the reader thread,
so a slow consumer slows the host through TCP), IN URBs join their endpoint's pending queue, and
CMD_UNLINK removes a pending URB. The *writer* is the only thread that sends: it drains the queued
replies and completes pending bulk-IN URBs, oldest first, from the bytes `send` queued (each gets at
most its transfer_buffer_length; a URB with nothing to send stays pending, as a real device NAKs).
The interrupt-IN (notification) URBs stay pending until unlinked or the host leaves.

Protocol errors (unknown command, wrong devid, an OUT URB over `MAX_TRANSFER`) end the session: the
connection is dropped, the device becomes free for the next import, the server goes on.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
from collections import deque
from collections.abc import Callable

from eyehil.emulator.device.links.usbip.control import CdcAcmControl
from eyehil.protocols.usbip.descriptors import EP_DATA_IN, EP_DATA_OUT, EP_NOTIFY, SetupPacket
from eyehil.protocols.usbip.messages import UsbipError
from eyehil.protocols.usbip.urb import (
    URB_HEADER_SIZE,
    URB_STALL,
    URB_UNLINKED,
    CmdSubmit,
    CmdUnlink,
    Direction,
    RetSubmit,
    RetUnlink,
    decode_urb_header,
    with_data,
)

log = logging.getLogger(__name__)
MAX_TRANSFER = 16 * 1024 * 1024
_BULK_IN, _NOTIFY_IN, _BULK_OUT = EP_DATA_IN & 0x0F, EP_NOTIFY & 0x0F, EP_DATA_OUT & 0x0F


def call_consumer(callback: Callable[..., None] | None, *args: object) -> None:
    """Call a consumer's callback; a bug in the consumer is logged and must not take the link down."""
    try:
        if callback:
            callback(*args)
    except Exception:
        log.exception("%s callback failed", getattr(callback, "__name__", "consumer"))


def recv_exact(sock: socket.socket, size: int) -> bytes | None:
    """Exactly `size` bytes from the socket, or None if the peer closed it first."""
    buf = bytearray(size)
    view, got = memoryview(buf), 0
    while got < size:
        n = sock.recv_into(view[got:])
        if n == 0:
            return None
        got += n
    return bytes(buf)


class UsbipSession:
    """The URB phase of one imported connection; `run` returns when the host leaves or `close` is called."""

    def __init__(self, sock: socket.socket, devid: int, control: CdcAcmControl,
                 on_data: Callable[[bytes], None], max_buffer: int, name: str) -> None:
        self._sock, self._devid, self._control, self._on_data = sock, devid, control, on_data
        self._max_buffer, self._name = max_buffer, name
        self._cond = threading.Condition()
        self._replies: deque[bytes] = deque()
        self._pending: dict[int, deque[CmdSubmit]] = {_BULK_IN: deque(), _NOTIFY_IN: deque()}
        self._tx = bytearray()
        self._closed = False
        self.bytes_dropped = 0

    @property
    def tx_pending(self) -> int:
        """Bytes queued by `send` that the host has not fetched yet."""
        with self._cond:
            return len(self._tx)

    def send(self, data: bytes) -> int:
        """Queue device -> host bytes; returns how many fit in the buffer (the rest is dropped and counted)."""
        with self._cond:
            if self._closed:
                return 0
            n = min(len(data), max(0, self._max_buffer - len(self._tx)))
            self._tx += data[:n]
            self.bytes_dropped += len(data) - n
            if n:
                self._cond.notify_all()
            return n

    def close(self) -> None:
        """Stop both threads: the writer wakes up, the reader's socket is shut down (idempotent)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)

    def run(self) -> None:
        """Serve URBs until the host disconnects, sends garbage, or `close` is called."""
        writer = threading.Thread(target=self._write_loop, name=f"{self._name}-writer", daemon=True)
        writer.start()
        try:
            self._read_loop()
        except (OSError, UsbipError) as exc:
            log.debug("%s: session ends: %s", self._name, exc)
        finally:
            self.close()
            writer.join()

    def _read_loop(self) -> None:
        while (header := recv_exact(self._sock, URB_HEADER_SIZE)) is not None:
            message = decode_urb_header(header)
            if message.devid != self._devid:
                raise UsbipError(f"devid 0x{message.devid:08X} is not this device's 0x{self._devid:08X}")
            if isinstance(message, CmdUnlink):
                self._unlink(message)
            elif isinstance(message, CmdSubmit):
                if message.data_length > MAX_TRANSFER:
                    raise UsbipError(f"OUT transfer of {message.data_length} bytes exceeds {MAX_TRANSFER}")
                data = recv_exact(self._sock, message.data_length) if message.data_length else b""
                if data is None:
                    return
                self._submit(with_data(message, data))
            else:
                raise UsbipError(f"a host does not send {message.command.name}")

    def _submit(self, urb: CmdSubmit) -> None:
        if urb.ep == 0:
            self._reply(self._control_transfer(urb))
        elif urb.ep == _BULK_OUT and urb.direction == Direction.OUT:
            call_consumer(self._on_data, urb.data)
            self._reply(RetSubmit(urb.seqnum, 0, len(urb.data)))
        elif urb.ep in self._pending and urb.direction == Direction.IN and urb.transfer_buffer_length > 0:
            with self._cond:
                self._pending[urb.ep].append(urb)
                self._cond.notify_all()
        elif urb.ep in self._pending and urb.direction == Direction.IN:
            self._reply(RetSubmit(urb.seqnum, 0, 0))
        else:
            self._reply(RetSubmit(urb.seqnum, URB_STALL, 0))

    def _control_transfer(self, urb: CmdSubmit) -> RetSubmit:
        setup = SetupPacket.decode(urb.setup)
        reply = self._control.handle(setup, urb.data)
        if reply is None:
            return RetSubmit(urb.seqnum, URB_STALL, 0)
        if setup.is_in:
            data = reply[: urb.transfer_buffer_length]
            return RetSubmit(urb.seqnum, 0, len(data), data)
        return RetSubmit(urb.seqnum, 0, len(urb.data))

    def _unlink(self, command: CmdUnlink) -> None:
        status = 0
        with self._cond:
            for queue in self._pending.values():
                victim = next((u for u in queue if u.seqnum == command.unlink_seqnum), None)
                if victim is not None:
                    queue.remove(victim)
                    status = URB_UNLINKED
            self._replies.append(RetUnlink(command.seqnum, status).encode())
            self._cond.notify_all()

    def _reply(self, message: RetSubmit) -> None:
        with self._cond:
            self._replies.append(message.encode())
            self._cond.notify_all()

    def _write_loop(self) -> None:
        while (batch := self._next_batch()) is not None:
            try:
                self._sock.sendall(batch)
            except OSError as exc:
                log.debug("%s: send failed: %s", self._name, exc)
                self.close()
                return

    def _next_batch(self) -> bytes | None:
        """Wait for something to send; None once closed."""
        bulk_in = self._pending[_BULK_IN]
        with self._cond:
            while not self._closed and not self._replies and not (self._tx and bulk_in):
                self._cond.wait()
            if self._closed:
                return None
            chunks = list(self._replies)
            self._replies.clear()
            while self._tx and bulk_in:
                urb = bulk_in.popleft()
                data = bytes(self._tx[: urb.transfer_buffer_length])
                del self._tx[: len(data)]
                chunks.append(RetSubmit(urb.seqnum, 0, len(data), data).encode())
            return b"".join(chunks)
