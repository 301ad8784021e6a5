"""Device side of the USB link: the virtual tracker as a USB CDC-ACM device exported over USB/IP.

An adapter from `usbip_server.UsbipCdcServer` (a byte pipe) to the `DeviceLink` interface of
`links.py`. A host opens ``usbip://host:port/1-1`` with `eyehil.drivers.links.usbip`, or a Linux host attaches
it with ``usbip attach -r host -b 1-1`` and gets a /dev/ttyACM* (docs/usbip.md). Bound to 127.0.0.1 by
default; `eyehil emulate --link usbip` serves the standard USB/IP port 3240, the class defaults to any free port.
"""

from __future__ import annotations

from collections.abc import Callable

from eyehil.emulator.device.links.base import register_open, unregister
from eyehil.emulator.device.links.usbip.server import UsbipCdcServer


class UsbipLink:
    """`DeviceLink` over a USB/IP-exported CDC-ACM device."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0, busid: str = "1-1") -> None:
        self._receive: Callable[[bytes], None] = lambda data: None
        self._reset: Callable[[], None] = lambda: None
        self._server = UsbipCdcServer(lambda data: self._receive(data), host=host, port=port, busid=busid,
                                      on_attach=lambda: self._reset())
        self._busid, self._host = busid, host
        self.name = "usbip (not started)"
        self.url = ""

    @property
    def connected(self) -> bool:
        return self._server.attached

    def attach(self, receive: Callable[[bytes], None], reset: Callable[[], None]) -> None:
        """Start serving; `receive` gets the host's bulk-OUT bytes, `reset` runs when a new host imports."""
        self._receive, self._reset = receive, reset
        self._server.start()
        self.url = f"usbip://{self._host}:{self._server.port}/{self._busid}"
        self.name = f"usbip {self._host}:{self._server.port} busid {self._busid}"
        register_open(self, self.name)

    def send(self, data: bytes) -> None:
        self._server.send(data)

    def backlog(self) -> int:
        return self._server.tx_pending

    def close(self) -> None:
        self._server.close()
        unregister(self)
