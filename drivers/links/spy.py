"""``spy://<inner URL>``: any link, with every byte in both directions hex-dumped (like pyserial's spy://).

    spy:///dev/pts/5           spy://socket://127.0.0.1:5555           spy://loop://?clock=fast

One line per read or write, to stderr by default::

    +0.001234 TX 8 | 06 45 48 01 02 01 01 01 | .EH.....
    +0.002010 RX 48 | 2c 45 48 01 82 01 01 01 ... | ,EH.....

(seconds since the link opened, direction, byte count, at most 32 bytes shown per line and 16 per row).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

ROW = 16
MAX_SHOWN = 32


def hexdump(data: bytes) -> list[str]:
    """Rows of hex and printable ASCII for `data` (at most `MAX_SHOWN` bytes, '...' if cut)."""
    shown = data[:MAX_SHOWN]
    rows = []
    for i in range(0, len(shown), ROW):
        chunk = shown[i : i + ROW]
        text = "".join(chr(b) if 32 <= b < 127 else "." for b in chunk)
        rows.append(f"{chunk.hex(' '):<{3 * ROW - 1}} | {text}")
    if len(data) > MAX_SHOWN:
        rows.append(f"... {len(data) - MAX_SHOWN} more")
    return rows


class SpyLink:
    """Wraps a SerialLike; forwards everything and logs the bytes."""

    def __init__(self, inner, out: TextIO | None = None) -> None:
        """Log the traffic of `inner` to `out` (default sys.stderr)."""
        self.inner, self.out = inner, out or sys.stderr
        self._t0 = time.monotonic()
        if hasattr(inner, "fileno"):
            self.fileno = inner.fileno

    def _log(self, direction: str, data: bytes) -> None:
        if data:
            stamp = f"+{time.monotonic() - self._t0:.6f} {direction} {len(data)}"
            for row in hexdump(bytes(data)):
                print(f"{stamp} | {row}", file=self.out)
                stamp = " " * len(stamp)

    @property
    def timeout(self) -> float | None:
        return self.inner.timeout

    @timeout.setter
    def timeout(self, value: float | None) -> None:
        self.inner.timeout = value

    @property
    def in_waiting(self) -> int:
        return self.inner.in_waiting

    def read(self, size: int = 1) -> bytes:
        data = self.inner.read(size)
        self._log("RX", data)
        return data

    def write(self, data: bytes) -> int | None:
        self._log("TX", data)
        return self.inner.write(data)

    def reset_input_buffer(self) -> None:
        if hasattr(self.inner, "reset_input_buffer"):
            self.inner.reset_input_buffer()

    def close(self) -> None:
        self.inner.close()


def open_spy(url: str, timeout: float | None = 0.0, out: TextIO | None = None) -> SpyLink:
    """Open the URL after ``spy://`` and wrap it."""
    from eyehil.drivers.links import open_link

    inner = url[len("spy://"):]
    if not inner:
        raise ValueError("spy:// needs an inner URL, e.g. spy://socket://127.0.0.1:5555")
    return SpyLink(open_link(inner, timeout), out)
