"""A small USB/IP client: list a server's devices, import one, submit URBs and collect their completions.

No kernel module and no third-party package: the host talks USB/IP itself over TCP (the codecs are in
`eyehil.protocols.usbip.messages` and `eyehil.protocols.usbip.urb`). One reader thread receives every RET_SUBMIT/RET_UNLINK
and completes the matching `Urb` (its event is set, then its callback, if any, runs in the reader
thread); submitting and unlinking are thread-safe. When the connection breaks, every outstanding URB
completes with `URB_SHUTDOWN` and `on_broken` is called once.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import count

import serial

from eyehil.protocols.usbip.descriptors import SetupPacket
from eyehil.protocols.usbip.messages import (
    OP_HEADER,
    USB_DEVICE,
    USB_INTERFACE,
    USBIP_PORT,
    OpCode,
    OpHeader,
    OpStatus,
    UsbDevice,
    UsbInterface,
    UsbipError,
    encode_import_request,
)
from eyehil.protocols.usbip.urb import (
    URB_HEADER_SIZE,
    URB_UNLINKED,
    CmdSubmit,
    CmdUnlink,
    Direction,
    RetSubmit,
    RetUnlink,
    data_to_read,
    decode_urb_header,
)

URB_SHUTDOWN = -108  # -ESHUTDOWN: the connection went away before the URB completed


class UsbipLinkError(serial.SerialException):
    """The USB/IP server refused, stalled a request, or the connection broke."""


@dataclass(eq=False)
class Urb:
    """One submitted URB; `status` and `data` are set when `done` is."""

    seqnum: int
    ep: int
    direction: int
    callback: Callable[[Urb], None] | None = None
    status: int | None = None
    data: bytes = b""
    done: threading.Event = field(default_factory=threading.Event)

    def complete(self, status: int, data: bytes = b"") -> None:
        self.status, self.data = status, data
        self.done.set()
        if self.callback:
            self.callback(self)


def recv_exact(sock: socket.socket, size: int) -> bytes:
    """Exactly `size` bytes; UsbipLinkError if the server closes the connection first."""
    buf = bytearray(size)
    view, got = memoryview(buf), 0
    while got < size:
        n = sock.recv_into(view[got:])
        if n == 0:
            raise UsbipLinkError("USB/IP server closed the connection")
        got += n
    return bytes(buf)


def _op(host: str, port: int, request: bytes, timeout: float) -> tuple[socket.socket, OpHeader]:
    sock = socket.create_connection((host, port), timeout=timeout)
    try:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.sendall(request)
        return sock, OpHeader.decode(recv_exact(sock, OP_HEADER.size))
    except BaseException:
        sock.close()
        raise


def _read_device(sock: socket.socket, with_interfaces: bool) -> UsbDevice:
    device, n_interfaces = UsbDevice.decode(recv_exact(sock, USB_DEVICE.size))
    if not with_interfaces:
        return device
    interfaces = tuple(UsbInterface.decode(recv_exact(sock, USB_INTERFACE.size)) for _ in range(n_interfaces))
    return UsbDevice(**{**device.__dict__, "interfaces": interfaces})


def list_devices(host: str, port: int = USBIP_PORT, timeout: float = 5.0) -> list[UsbDevice]:
    """OP_REQ_DEVLIST: the devices a USB/IP server exports."""
    sock, header = _op(host, port, OpHeader(OpCode.REQ_DEVLIST).encode(), timeout)
    with sock:
        if header.code != OpCode.REP_DEVLIST or header.status != OpStatus.OK:
            raise UsbipLinkError(f"devlist refused: {header}")
        (n,) = struct.unpack(">I", recv_exact(sock, 4))
        return [_read_device(sock, with_interfaces=True) for _ in range(n)]


class UsbipClient:
    """An imported device: submit URBs, wait for them, unlink them."""

    def __init__(self, sock: socket.socket, device: UsbDevice, on_broken: Callable[[], None] | None = None) -> None:
        self.device, self._sock, self._on_broken = device, sock, on_broken
        self._lock, self._send_lock = threading.Lock(), threading.Lock()
        self._urbs: dict[int, Urb] = {}
        self._unlinks: dict[int, Urb] = {}
        self._seq = count(1)
        self.broken: BaseException | None = None
        sock.settimeout(None)
        self._reader = threading.Thread(target=self._read_loop, name="eyehil-usbip-client-reader", daemon=True)
        self._reader.start()

    @classmethod
    def open(cls, host: str, port: int = USBIP_PORT, busid: str | None = None, timeout: float = 5.0,
             on_broken: Callable[[], None] | None = None) -> UsbipClient:
        """Import `busid` (default: the server's first device) and start the reader thread."""
        if busid is None:
            devices = list_devices(host, port, timeout)
            if not devices:
                raise UsbipLinkError(f"USB/IP server {host}:{port} exports no device")
            busid = devices[0].busid
        sock, header = _op(host, port, encode_import_request(busid), timeout)
        try:
            if header.code != OpCode.REP_IMPORT or header.status != OpStatus.OK:
                raise UsbipLinkError(f"import of {busid} refused: {_status_name(header.status)}")
            return cls(sock, _read_device(sock, with_interfaces=False), on_broken)
        except BaseException:
            sock.close()
            raise

    def submit(self, ep: int, direction: int, length: int = 0, data: bytes = b"", setup: bytes = bytes(8),
               callback: Callable[[Urb], None] | None = None) -> Urb:
        """Send CMD_SUBMIT (for OUT, `length` is len(data)); the URB completes later."""
        length = len(data) if direction == Direction.OUT else length
        with self._lock:
            if self.broken:
                raise UsbipLinkError(f"USB/IP link lost: {self.broken}")
            urb = Urb(next(self._seq) & 0xFFFFFFFF, ep & 0x0F, direction, callback)
            self._urbs[urb.seqnum] = urb
        self._send(CmdSubmit(urb.seqnum, self.device.devid, direction, ep & 0x0F, length, setup, data=data).encode())
        return urb

    def unlink(self, urb: Urb) -> None:
        """Ask the server to cancel `urb`; it completes with URB_UNLINKED unless it had completed already."""
        with self._lock:
            seqnum = next(self._seq) & 0xFFFFFFFF
            self._unlinks[seqnum] = urb
        self._send(CmdUnlink(seqnum, self.device.devid, urb.seqnum, urb.direction, urb.ep).encode())

    def control(self, setup: SetupPacket, data: bytes = b"", timeout: float = 5.0) -> bytes:
        """A control transfer on endpoint 0; returns the IN data stage. UsbipLinkError on stall or timeout."""
        direction = Direction.IN if setup.is_in else Direction.OUT
        urb = self.submit(0, direction, setup.length, data, setup.encode())
        if not urb.done.wait(timeout):
            self.unlink(urb)
            raise UsbipLinkError(f"control request {setup} timed out")
        if urb.status != 0:
            raise UsbipLinkError(f"control request {setup} failed with status {urb.status}")
        return urb.data

    def close(self) -> None:
        """Drop the connection (the server sees the host detach) and join the reader thread."""
        with contextlib.suppress(OSError):
            self._sock.shutdown(socket.SHUT_RDWR)
        self._reader.join()
        self._sock.close()

    def _send(self, message: bytes) -> None:
        try:
            with self._send_lock:
                self._sock.sendall(message)
        except OSError as exc:
            raise UsbipLinkError(f"USB/IP send failed: {exc}") from exc

    def _read_loop(self) -> None:
        try:
            while True:
                self._dispatch(decode_urb_header(recv_exact(self._sock, URB_HEADER_SIZE)))
        except (OSError, UsbipError, UsbipLinkError) as exc:
            self._fail_all(exc)

    def _dispatch(self, message: object) -> None:
        if isinstance(message, RetSubmit):
            with self._lock:
                urb = self._urbs.pop(message.seqnum, None)
            if urb is None:
                raise UsbipError(f"RET_SUBMIT for unknown seqnum {message.seqnum}")
            n = data_to_read(message, urb.direction)
            urb.complete(message.status, recv_exact(self._sock, n) if n else b"")
        elif isinstance(message, RetUnlink):
            with self._lock:
                urb = self._unlinks.pop(message.seqnum, None)
                if urb is None or message.status != URB_UNLINKED or self._urbs.pop(urb.seqnum, None) is None:
                    return  # it had completed already (its RET_SUBMIT came first)
            urb.complete(URB_UNLINKED)
        else:
            raise UsbipError(f"a server does not send {type(message).__name__}")

    def _fail_all(self, exc: BaseException) -> None:
        with self._lock:
            self.broken = exc
            pending = list(self._urbs.values())
            self._urbs.clear()
        for urb in pending:
            urb.complete(URB_SHUTDOWN)
        if self._on_broken:
            self._on_broken()


def _status_name(status: int) -> str:
    try:
        return OpStatus(status).name
    except ValueError:
        return f"status {status}"
