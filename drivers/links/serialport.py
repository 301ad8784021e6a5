"""Serial ports and pyserial URL handlers: a device path (/dev/ttyACM0, a pseudo-terminal, COM3) or
``socket://host:port`` / ``rfc2217://host:port``, opened with `serial.serial_for_url`.

Baud rate and framing matter only on a real UART; USB CDC-ACM ports and pseudo-terminals ignore them.
The default, 921600 baud 8N1, carries about 1245 FEATURES per second of one eye with two glints
(docs/protocol.md section 7); pass ``baudrate=`` for other set-ups.
"""

from __future__ import annotations

import serial

DEFAULT_BAUDRATE = 921_600


def open_serial(url: str, timeout: float | None = 0.0, baudrate: int = DEFAULT_BAUDRATE) -> serial.SerialBase:
    """Open a device path or pyserial URL; raise OSError (serial.SerialException) if it cannot be opened."""
    return serial.serial_for_url(url, baudrate=baudrate, timeout=timeout, write_timeout=2.0)
