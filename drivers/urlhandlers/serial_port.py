"""`EyehilSerial`: an eyehil link (`eyehil.drivers.links.open_link`) behind pyserial's `SerialBase` interface.

Serial settings (baud rate, parity, ...) are accepted and ignored: the link's own speed is what it is.
`read` honours `timeout` as pyserial does (None blocks, 0 returns what is there); `write_timeout` is not used.
"""

from __future__ import annotations

import serial

from eyehil.drivers.errors import TrackerError
from eyehil.drivers.links import SerialLike, open_link

PREFIX = "eyehil+"


def inner_url(url: str) -> str:
    """The eyehil URL behind a pyserial one: ``eyehil+loop://?x`` -> ``loop://?x``."""
    if not url.lower().startswith(PREFIX):
        raise serial.SerialException(f"not an eyehil URL: {url!r} (expected {PREFIX}<scheme>://...)")
    return url[len(PREFIX):]


class EyehilSerial(serial.SerialBase):
    """A `serial.Serial`-compatible port over an eyehil link."""

    _link: SerialLike | None = None

    def open(self) -> None:
        if self._port is None:
            raise serial.SerialException("port must be configured before it can be used")
        if self.is_open:
            raise serial.SerialException("port already open")
        try:
            self._link = open_link(inner_url(self._port), timeout=self._timeout)
        except TrackerError as exc:
            raise serial.SerialException(str(exc)) from exc
        self.is_open = True

    def _reconfigure_port(self, force_update: bool = False) -> None:
        if self._link is not None:
            self._link.timeout = self._timeout

    def close(self) -> None:
        if self._link is not None:
            self._link.close()
            self._link = None
        self.is_open = False

    def _open_link(self) -> SerialLike:
        if self._link is None:
            raise serial.PortNotOpenError()
        return self._link

    @property
    def in_waiting(self) -> int:
        return int(getattr(self._open_link(), "in_waiting", 0))

    def read(self, size: int = 1) -> bytes:
        link = self._open_link()
        link.timeout = self._timeout
        try:
            return bytes(link.read(size))
        except OSError as exc:
            raise serial.SerialException(f"{self._port}: {exc}") from exc

    def write(self, data: bytes) -> int:
        link = self._open_link()
        data = memoryview(serial.to_bytes(data)).tobytes()
        try:
            link.write(data)
        except OSError as exc:
            raise serial.SerialException(f"{self._port}: {exc}") from exc
        return len(data)

    def reset_input_buffer(self) -> None:
        reset = getattr(self._open_link(), "reset_input_buffer", None)
        if reset is not None:
            reset()

    def reset_output_buffer(self) -> None:
        self._open_link()

    def fileno(self) -> int:
        return self._open_link().fileno()  # type: ignore[attr-defined]
