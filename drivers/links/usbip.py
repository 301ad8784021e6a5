"""The host side of the USB link: `usbip://host[:port][/busid]` opened as a pyserial-like port.

The host speaks USB/IP itself (`eyehil.drivers.links.usbip_client`): it imports the CDC-ACM device over TCP,
configures it as a CDC-ACM driver would (GET_DESCRIPTOR device and configuration, SET_CONFIGURATION,
SET_LINE_CODING at `baudrate` 8N1, SET_CONTROL_LINE_STATE with DTR and RTS), then moves data in bulk
URBs: `write` sends OUT URBs of up to 64 KiB and waits for their completion; `urbs_in_flight` bulk-IN
URBs of `read_chunk` bytes are kept outstanding and their data buffered for `read`. Like a tty, the
host stops asking for data while `rx_limit` bytes are unread (the device then sees backpressure).
No kernel module, no third-party package. Port 3240 by default; busid: the server's first device.

    port = UsbipSerial.from_url("usbip://127.0.0.1:3240/1-1", timeout=0.5)
    port.write(b"...")                  # -> number of bytes written
    data = port.read(100)               # at most 100 bytes; fewer if `timeout` seconds pass
    port.close()

`read`/`write` follow pyserial: `timeout` None blocks, 0 does not wait, x > 0 waits at most x seconds;
errors are `serial.SerialException` (`UsbipLinkError`), a write timeout `serial.SerialTimeoutException`.
"""

from __future__ import annotations

import struct
import threading
import time
from typing import Any
from urllib.parse import urlsplit

import serial

from eyehil.drivers.links.usbip_client import Urb, UsbipClient, UsbipLinkError
from eyehil.protocols.usbip.descriptors import (
    CLASS_OUT_INTERFACE,
    LINE_STATE_DTR,
    LINE_STATE_RTS,
    CdcEndpoints,
    DescriptorType,
    LineCoding,
    Request,
    SetupPacket,
    find_cdc_endpoints,
)
from eyehil.protocols.usbip.messages import USBIP_PORT
from eyehil.protocols.usbip.urb import Direction

WRITE_CHUNK = 64 * 1024


class UsbipSerial:
    """A CDC-ACM device imported over USB/IP, with pyserial's read/write/timeout interface."""

    _eps: CdcEndpoints  # found in the configuration descriptor when the port opens

    def __init__(self, host: str, port: int = USBIP_PORT, busid: str | None = None, timeout: float | None = None,
                 write_timeout: float | None = None, baudrate: int = 115200, read_chunk: int = 64 * 1024,
                 urbs_in_flight: int = 2, rx_limit: int = 4 * 1024 * 1024, connect_timeout: float = 5.0) -> None:
        address = f"[{host}]" if ":" in host else host
        self.port = self.name = f"usbip://{address}:{port}" + (f"/{busid}" if busid else "")
        self.timeout, self.write_timeout = timeout, write_timeout
        self._read_chunk, self._in_flight_target, self._rx_limit = read_chunk, urbs_in_flight, rx_limit
        self._cond = threading.Condition()
        self._rx = bytearray()
        self._in_flight = 0
        self._wanted = 0
        self._closed = False
        self._baudrate, self._line_state = baudrate, LINE_STATE_DTR | LINE_STATE_RTS
        self._client = UsbipClient.open(host, port, busid, connect_timeout, on_broken=self._wake)
        try:
            self._configure()
        except BaseException:
            self._client.close()
            raise
        self._refill()

    @classmethod
    def from_url(cls, url: str, **kwargs: Any) -> UsbipSerial:
        """Open `usbip://host[:port][/busid]`; keyword arguments as for the constructor."""
        parts = urlsplit(url)
        if parts.scheme != "usbip" or not parts.hostname:
            raise ValueError(f"not a usbip://host[:port][/busid] URL: {url!r}")
        busid = parts.path.strip("/") or None
        return cls(parts.hostname, parts.port or USBIP_PORT, busid, **kwargs)

    def __enter__(self) -> UsbipSerial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        return not self._closed

    @property
    def in_waiting(self) -> int:
        """Bytes received and not read yet."""
        with self._cond:
            return len(self._rx)

    @property
    def baudrate(self) -> int:
        return self._baudrate

    @baudrate.setter
    def baudrate(self, value: int) -> None:
        self._baudrate = value
        self._control(CLASS_OUT_INTERFACE, Request.SET_LINE_CODING, 0, LineCoding(value).encode())

    @property
    def dtr(self) -> bool:
        return bool(self._line_state & LINE_STATE_DTR)

    @dtr.setter
    def dtr(self, value: bool) -> None:
        self._line_state = (self._line_state & ~LINE_STATE_DTR) | (LINE_STATE_DTR if value else 0)
        self._control(CLASS_OUT_INTERFACE, Request.SET_CONTROL_LINE_STATE, self._line_state)

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes: returns when `size` are there or `timeout` has passed (pyserial semantics)."""
        self._check_open()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        with self._cond:
            self._wanted = size  # a read larger than rx_limit must not be throttled
        self._refill()
        with self._cond:
            while len(self._rx) < size and not self._client.broken and not self._closed:
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    break
                self._cond.wait(remaining)
            data = bytes(self._rx[:size])
            del self._rx[:size]
            self._wanted = 0
        if not data and self._client.broken:
            raise UsbipLinkError(f"USB/IP link lost: {self._client.broken}")
        self._refill()
        return data

    def write(self, data: bytes) -> int:
        """Send `data` in bulk-OUT URBs and wait until the device has taken all of it; returns len(data)."""
        self._check_open()
        data = bytes(data)
        deadline = None if self.write_timeout is None else time.monotonic() + self.write_timeout
        urbs = [self._client.submit(self._eps.bulk_out, Direction.OUT, data=data[i: i + WRITE_CHUNK])
                for i in range(0, len(data), WRITE_CHUNK)]
        for urb in urbs:
            if not urb.done.wait(None if deadline is None else max(0.0, deadline - time.monotonic())):
                for late in urbs:
                    self._client.unlink(late)
                raise serial.SerialTimeoutException("Write timeout")
            if urb.status != 0:
                raise UsbipLinkError(f"bulk OUT failed with status {urb.status}")
        return len(data)

    def flush(self) -> None:
        """Nothing to do: `write` returns once the device has the data."""

    def reset_input_buffer(self) -> None:
        with self._cond:
            self._rx.clear()
        self._refill()

    def close(self) -> None:
        """Detach from the device (idempotent)."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
        self._client.close()

    def _check_open(self) -> None:
        if self._closed:
            raise serial.PortNotOpenError()

    def _configure(self) -> None:
        get = Request.GET_DESCRIPTOR
        self._client.control(SetupPacket(0x80, get, DescriptorType.DEVICE << 8, 0, 18))
        head = self._client.control(SetupPacket(0x80, get, DescriptorType.CONFIGURATION << 8, 0, 9))
        if len(head) < 9:
            raise UsbipLinkError("short configuration descriptor")
        total = struct.unpack_from("<H", head, 2)[0]
        config = self._client.control(SetupPacket(0x80, get, DescriptorType.CONFIGURATION << 8, 0, total))
        self._eps = find_cdc_endpoints(config)
        self._client.control(SetupPacket(0x00, Request.SET_CONFIGURATION, config[5]))
        self._control(CLASS_OUT_INTERFACE, Request.SET_LINE_CODING, 0, LineCoding(self._baudrate).encode())
        self._control(CLASS_OUT_INTERFACE, Request.SET_CONTROL_LINE_STATE, self._line_state)

    def _control(self, request_type: int, request: int, value: int, data: bytes = b"") -> None:
        self._client.control(SetupPacket(request_type, request, value, self._eps.comm_interface, len(data)), data)

    def _refill(self) -> None:
        """Keep `urbs_in_flight` bulk-IN URBs outstanding while fewer than `rx_limit` bytes are unread."""
        with self._cond:
            throttled = self._closed or self._client.broken or len(self._rx) >= max(self._rx_limit, self._wanted)
            missing = 0 if throttled else self._in_flight_target - self._in_flight
            self._in_flight += missing
        for _ in range(missing):
            try:
                self._client.submit(self._eps.bulk_in, Direction.IN, self._read_chunk, callback=self._received)
            except UsbipLinkError:
                return

    def _received(self, urb: Urb) -> None:
        with self._cond:
            self._in_flight -= 1
            if urb.status == 0:
                self._rx += urb.data
            self._cond.notify_all()
        if urb.status == 0:
            self._refill()

    def _wake(self) -> None:
        with self._cond:
            self._cond.notify_all()
