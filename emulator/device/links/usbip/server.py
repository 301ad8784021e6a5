"""The virtual tracker as a USB device: a USB/IP server exporting one CDC-ACM (virtual serial) device.

A byte pipe, independent of the tracker: bytes the host writes to the serial port arrive at
`on_data(bytes)`; bytes given to `send` reach the host's reads. A Linux host attaches it with
`usbip attach -r HOST -b 1-1` (module vhci-hcd) and gets a /dev/ttyACM*; `eyehil.drivers.links.usbip` opens it
directly, without the kernel. See docs/usbip.md.

    server = UsbipCdcServer(on_data=core.feed, on_attach=core.connection_reset).start()  # 127.0.0.1, ephemeral
    url = f"usbip://127.0.0.1:{server.port}"               # server.port: the bound port
    server.send(reply_bytes)                                # queued until the host reads
    server.close()                                          # joins every thread, closes every socket

Threads (named "eyehil-usbip-..."): one accepts; one per connection answers its op request (a devlist,
then the connection closes, as usbipd does) and, after a successful import, reads its URBs; a writer per
session (see `usbip_session`). `on_attach()` runs when a host imports the device, before any of its data.
One host at a time: a second import gets ST_DEV_BUSY. Limits: at most `MAX_CONNECTIONS` connections at
once (more are closed, `connections_refused`); a connection has `OP_TIMEOUT` s in total for its op request;
an imported host that has no IN URB waiting and sends nothing for `usbip_session.IMPORT_LEASE_S` loses the
device (the lease); per session at most `MAX_PENDING_URBS` IN URBs per endpoint and `MAX_REPLY_BYTES` of
unread replies (beyond: the session ends). Bytes sent while no host is attached are dropped
(counted in `bytes_dropped`), as are bytes beyond `max_buffer` still queued. A bad op header (version
other than 0x0111, unknown code) closes the connection.
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable
from itertools import count

from eyehil.emulator.device.links.listen import create_server
from eyehil.emulator.device.links.usbip.control import CdcAcmControl
from eyehil.emulator.device.links.usbip.session import UsbipSession, call_consumer, recv_exact
from eyehil.protocols.usbip.descriptors import CdcAcmDescriptors, LineCoding
from eyehil.protocols.usbip.messages import (
    BUSID_SIZE,
    OP_HEADER,
    USBIP_VERSION,
    OpCode,
    OpHeader,
    OpStatus,
    UsbipError,
    cdc_acm_device,
    decode_busid,
    encode_devlist_reply,
    encode_import_reply,
)

log = logging.getLogger(__name__)
OP_TIMEOUT = 10.0  # seconds a new connection has to send its whole op request (a total, not per recv)
MAX_CONNECTIONS = 8  # connections served at once (each has a thread): more are closed at once, counted
JOIN_TIMEOUT = 10.0


class UsbipCdcServer:
    """A USB/IP server exporting one CDC-ACM device as a generic byte pipe (thread-safe)."""

    def __init__(self, on_data: Callable[[bytes], None], host: str = "127.0.0.1", port: int = 0,
                 busid: str = "1-1", serial: str = "EYEHIL-0001", max_buffer: int = 8 * 1024 * 1024,
                 on_attach: Callable[[], None] | None = None) -> None:
        self.device = cdc_acm_device(busid)
        self.control = CdcAcmControl(CdcAcmDescriptors(serial))
        self._on_data, self._on_attach = on_data, on_attach
        self._address, self._max_buffer = (host, port), max_buffer
        self._cond = threading.Condition()
        self._session: UsbipSession | None = None
        self._connections: dict[threading.Thread, socket.socket] = {}
        self._listener: socket.socket | None = None
        self._wake: tuple[socket.socket, socket.socket] | None = None
        self._accept_thread: threading.Thread | None = None
        self._closing = False
        self._ids = count(1)
        self._dropped = 0
        self._bound_port = 0
        self.connections_refused = 0
        self.imports_busy = 0  # imports answered DEV_BUSY

    def __enter__(self) -> UsbipCdcServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def port(self) -> int:
        """The bound TCP port (the requested one before `start`)."""
        return self._bound_port or self._address[1]

    @property
    def attached(self) -> bool:
        """True while a host has the device imported."""
        with self._cond:
            return self._session is not None

    @property
    def dtr(self) -> bool:
        """The host's DTR line (set when a serial program opens the port)."""
        return self.control.dtr

    @property
    def line_coding(self) -> LineCoding:
        return self.control.line_coding

    @property
    def bytes_dropped(self) -> int:
        """Bytes `send` could not queue: no host attached, or the buffer was full."""
        with self._cond:
            return self._dropped + (self._session.bytes_dropped if self._session else 0)

    def wait_attached(self, timeout: float | None = None, attached: bool = True) -> bool:
        """Wait until a host is attached (or, with attached=False, until none is); False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: (self._session is not None) == attached, timeout)

    def send(self, data: bytes) -> int:
        """Queue bytes for the host's reads; returns how many were accepted (0 if no host is attached)."""
        with self._cond:
            session = self._session
            if session is None:
                self._dropped += len(data)
                return 0
        return session.send(data)

    @property
    def tx_pending(self) -> int:
        """Bytes queued by `send` that the attached host has not read yet."""
        with self._cond:
            session = self._session
        return session.tx_pending if session else 0

    def start(self) -> UsbipCdcServer:
        """Bind and listen, then accept connections in a background thread; returns self."""
        if self._listener is not None or self._closing:
            raise RuntimeError("a server starts once")
        family = socket.AF_INET6 if ":" in self._address[0] else socket.AF_INET
        listener = create_server("usbip", *self._address, family=family)
        self._listener, self._wake = listener, socket.socketpair()
        self._bound_port = listener.getsockname()[1]
        self._accept_thread = threading.Thread(target=self._accept_loop, name="eyehil-usbip-accept", daemon=True)
        self._accept_thread.start()
        return self

    def close(self) -> None:
        """Stop accepting, drop the attached host and every connection, join all threads (idempotent)."""
        with self._cond:
            if self._closing:
                return
            self._closing = True
            session = self._session
        if self._wake:
            self._wake[1].send(b"\0")
        if self._accept_thread:
            self._accept_thread.join(JOIN_TIMEOUT)
        with self._cond:
            connections = dict(self._connections)
        if session:
            session.close()
        for conn in connections.values():
            _shutdown(conn)
        for thread in connections:
            thread.join(JOIN_TIMEOUT)
        for sock in (self._listener, *(self._wake or ())):
            if sock:
                sock.close()

    def _accept_loop(self) -> None:
        assert self._listener and self._wake
        with selectors.DefaultSelector() as selector:
            selector.register(self._listener, selectors.EVENT_READ)
            selector.register(self._wake[0], selectors.EVENT_READ)
            while not any(key.fileobj is self._wake[0] for key, _ in selector.select()):
                try:
                    conn, _ = self._listener.accept()
                except OSError as exc:
                    log.debug("accept failed: %s", exc)
                    continue
                self._spawn(conn)

    def _spawn(self, conn: socket.socket) -> None:
        thread = threading.Thread(target=self._serve, args=(conn,), name=f"eyehil-usbip-conn-{next(self._ids)}",
                                  daemon=True)
        with self._cond:
            if self._closing:
                conn.close()
                return
            self._connections = {t: c for t, c in self._connections.items() if t.is_alive()}
            if len(self._connections) >= MAX_CONNECTIONS:
                self.connections_refused += 1
                conn.close()
                return
            self._connections[thread] = conn
        thread.start()

    def _serve(self, conn: socket.socket) -> None:
        try:
            conn.settimeout(OP_TIMEOUT)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._serve_op(conn)
        except (OSError, UsbipError) as exc:
            log.debug("connection dropped: %s", exc)
        finally:
            conn.close()  # the thread stays in _connections (pruned when dead) so that close() joins it

    def _serve_op(self, conn: socket.socket) -> None:
        deadline = time.monotonic() + OP_TIMEOUT
        raw = recv_exact(conn, OP_HEADER.size, deadline)
        if raw is None:
            return
        op = OpHeader.decode(raw)
        if op.version != USBIP_VERSION:
            raise UsbipError(f"USB/IP version 0x{op.version:04X} is not 0x{USBIP_VERSION:04X}")
        if op.code == OpCode.REQ_DEVLIST:
            conn.sendall(encode_devlist_reply([self.device]))
        elif op.code == OpCode.REQ_IMPORT:
            self._serve_import(conn, deadline)
        else:
            raise UsbipError(f"unknown op code 0x{op.code:04X}")

    def _serve_import(self, conn: socket.socket, deadline: float) -> None:
        raw = recv_exact(conn, BUSID_SIZE, deadline)
        if raw is None:
            return
        if decode_busid(raw) != self.device.busid:
            conn.sendall(encode_import_reply(None, OpStatus.NODEV))
            return
        session = self._claim(conn)
        if session is None:
            with self._cond:
                self.imports_busy += 1
            conn.sendall(encode_import_reply(None, OpStatus.DEV_BUSY))
            return
        try:
            call_consumer(self._on_attach)
            conn.sendall(encode_import_reply(self.device))
            conn.settimeout(None)
            session.run()
        finally:
            self._release(session)

    def _claim(self, conn: socket.socket) -> UsbipSession | None:
        with self._cond:
            if self._session is not None or self._closing:
                return None
            name = threading.current_thread().name
            self._session = UsbipSession(conn, self.device.devid, self.control, self._on_data, self._max_buffer, name)
            self._cond.notify_all()
            return self._session

    def _release(self, session: UsbipSession) -> None:
        session.close()
        with self._cond:
            self._dropped += session.bytes_dropped
            self._session = None
            self.control.reset()
            self._cond.notify_all()


def _shutdown(sock: socket.socket) -> None:
    with contextlib.suppress(OSError):
        sock.shutdown(socket.SHUT_RDWR)
