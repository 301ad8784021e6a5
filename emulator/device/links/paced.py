"""A link paced to a real link's byte rate on the device clock (`link_rate=12Mbit`, `--link-rate usb-fs`).

Emulated links are as fast as the machine (a pseudo-terminal carries about 200 MB/s, USB/IP 250 to 650 MB/s),
while a real full-speed USB CDC device carries about 1 MB/s and a UART at 115200 baud 11.5 kB/s. `PacedLink`
wraps any `DeviceLink` (links/base.py) and hands the device's output to it no faster than `rate` bytes per
second of device time (`eyehil.emulator.device.clock`: real, fast or manual), so a host tested against the
emulator meets the real link's bandwidth, and the device's own backpressure (FEATURES dropped beyond its output
limit, images dropped beyond the frame budget) acts as on the real link: `backlog()` counts the bytes waiting
in the pacer plus those in the wrapped link.

Pacing is a token bucket (`Pacer`): credit grows at `rate` bytes/s of device time; while the link idles
(nothing waits) it is capped at `burst` bytes (what the real link moves in one `granularity_us`: a USB
full-speed frame is 1 ms; default 1 ms), so idle time does not let a later burst exceed the real link, while
a busy link is credited all its time (a runner woken late catches up, never beyond the rate). Arithmetic is
in integer micro-bytes, so the bytes admitted by device time t are exact (tests run it on a `ManualClock`).
The runner (`LinkRunner`) calls `pump()` at each wake-up and sleeps at most `wake_delay_s()`.

Rate text (`parse_link_rate`): a number with a unit, per second (an optional ``/s`` may follow; units ignore
case, bits only as ``bit``): ``bit``, ``kbit``, ``Mbit``, ``Gbit`` (bits, divided by 8), ``B``, ``kB``, ``MB``,
``GB`` (bytes; k = 1000; a bare number is bytes), ``baud`` (a UART with 8N1 framing: 10 bit times per byte); or
a name: ``usb-fs`` (full-speed bulk: at most 19 packets of 64 bytes per 1 ms frame, 1,216,000 B/s), ``usb-hs``
(high-speed bulk: at most 13 packets of 512 bytes per 125 us microframe, 53,248,000 B/s). Limits: 10 B/s to
10 GB/s. The queue in front of the wrapped link holds at most `MAX_PACED_BACKLOG` bytes; output beyond it is
dropped and counted (``bytes_dropped``), as `fdlink` does.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable

from eyehil.emulator.device.clock import Clock

MAX_PACED_BACKLOG = 4 * 1024 * 1024  # bytes waiting in the pacer for a host that reads slower than the link
MIN_RATE_BPS, MAX_RATE_BPS = 10, 10_000_000_000  # bytes per second
NAMED_RATES = {"usb-fs": 19 * 64 * 1000, "usb-hs": 13 * 512 * 8000}  # bulk payload limits, B/s
_UNITS = {"bit": 1 / 8, "kbit": 1e3 / 8, "mbit": 1e6 / 8, "gbit": 1e9 / 8, "b": 1.0, "kb": 1e3, "mb": 1e6,
          "gb": 1e9, "baud": 1 / 10}
_RATE = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?(?:e[0-9]+)?)\s*([a-z]*?)(?:/s)?\s*$")
MICRO = 1_000_000


def parse_link_rate(text: str) -> int:
    """Bytes per second of a rate text (see the module docstring); raise `ValueError` if malformed or out of
    range. A bare number is bytes per second."""
    key = text.strip().lower()
    if key in NAMED_RATES:
        return NAMED_RATES[key]
    match = _RATE.match(key)
    if match is None or (match.group(2) or "b") not in _UNITS:
        raise ValueError(f"link rate {text!r}: expected e.g. 12Mbit, 1MB, 115200baud, usb-fs or usb-hs")
    rate = round(float(match.group(1)) * _UNITS[match.group(2) or "b"])
    if not MIN_RATE_BPS <= rate <= MAX_RATE_BPS:
        raise ValueError(f"link rate {text!r} = {rate} B/s outside {MIN_RATE_BPS}..{MAX_RATE_BPS} B/s")
    return rate


class Pacer:
    """Token bucket on device microseconds: `admit(now_us, want)` -> bytes that may go now (pure arithmetic)."""

    def __init__(self, rate_bps: int, start_us: int = 0, granularity_us: int = 1000) -> None:
        """`rate_bps` bytes per second; the bucket holds what the link moves in `granularity_us` (>= 1 byte)."""
        if not MIN_RATE_BPS <= rate_bps <= MAX_RATE_BPS or granularity_us < 1:
            raise ValueError(f"rate {rate_bps} B/s or granularity {granularity_us} us out of range")
        self.rate_bps = int(rate_bps)
        self.burst = max(1, -(-self.rate_bps * granularity_us // MICRO))  # bytes (rounded up)
        self._credit = 0  # micro-bytes (bytes x 1e6)
        self._t_us = int(start_us)
        self._idle = True  # the last `admit` gave all that was wanted: the link has idled since

    def _accrue(self, now_us: int) -> None:
        dt = max(0, int(now_us) - self._t_us)
        self._t_us = max(self._t_us, int(now_us))
        self._credit += self.rate_bps * dt
        if self._idle:  # an idle link stores at most one granule; a busy one transmitted all along
            self._credit = min(self._credit, self.burst * MICRO)

    def admit(self, now_us: int, want: int) -> int:
        """Bytes (<= `want`, the bytes waiting) that may be sent at `now_us`; they are taken from the bucket.
        Bytes admitted up to time t never exceed rate x (t - start) + burst."""
        self._accrue(now_us)
        n = min(int(want), self._credit // MICRO)
        self._credit -= n * MICRO
        self._idle = n == want
        return n

    def drained_us(self, now_us: int, want: int) -> int:
        """Device time by which all `want` bytes will have been admitted, if the link stays busy meanwhile."""
        self._accrue(now_us)
        need = int(want) * MICRO - self._credit
        return self._t_us if need <= 0 else self._t_us + -(-need // self.rate_bps)

    def due_us(self, now_us: int, want: int) -> int:
        """Device time at which `min(want, burst)` bytes will be admissible (`now_us` if already)."""
        self._accrue(now_us)
        need = min(int(want), self.burst) * MICRO - self._credit
        return self._t_us if need <= 0 else self._t_us + -(-need // self.rate_bps)


class PacedLink:
    """A `DeviceLink` passing output to `inner` at `rate_bps` bytes per second of `clock` time."""

    def __init__(self, inner, rate_bps: int, clock: Clock, granularity_us: int = 1000) -> None:
        """Wrap `inner` (any DeviceLink); `clock` is the device's clock."""
        self.inner, self.clock = inner, clock
        self.pacer = Pacer(rate_bps, clock.now_us(), granularity_us)
        self.name = f"{inner.name} at {rate_bps:,} B/s"
        self._queue = bytearray()
        self._lock = threading.Lock()
        self.bytes_dropped = 0

    @property
    def url(self) -> str:
        return self.inner.url

    @property
    def connected(self) -> bool:
        return self.inner.connected

    def attach(self, receive: Callable[[bytes], None], reset: Callable[[], None]) -> None:
        """Attach the wrapped link; a new host also forgets what waits in the pacer."""
        def on_reset() -> None:
            with self._lock:
                self._queue.clear()
            reset()

        self.inner.attach(receive, on_reset)

    def send(self, data: bytes) -> None:
        """Queue `data` behind what waits (dropped, counted, beyond `MAX_PACED_BACKLOG`), then pump."""
        if not self.inner.connected:
            return
        with self._lock:
            if len(self._queue) + len(data) > MAX_PACED_BACKLOG:
                self.bytes_dropped += len(data)
            else:
                self._queue += data
        self.pump()

    def pump(self) -> int:
        """Hand the wrapped link what the pacer admits now; return the bytes handed. On a lockstep clock (a fast
        clock without the wall floor: device time moves only when pushed) the transmission takes device time:
        the clock is pushed to when everything waiting has gone, as a streaming runner pushes it to the next
        sample (without this, nothing would move the clock while the device only answers, and a reply would
        wait for ever)."""
        with self._lock:
            n = 0
            if self._queue:
                now = self.clock.now_us()
                n = self.pacer.admit(now, len(self._queue))
                if n < len(self._queue) and _lockstep(self.clock):  # the link is busy from now on
                    self.clock.push(self.pacer.drained_us(now, len(self._queue) - n))
                    n += self.pacer.admit(self.clock.now_us(), len(self._queue) - n)
            data = bytes(self._queue[:n])
            del self._queue[:n]
        if data:
            self.inner.send(data)
        return len(data)

    @property
    def waiting(self) -> int:
        """Bytes in the pacer, not yet handed to the wrapped link."""
        return len(self._queue)

    def wake_delay_s(self) -> float | None:
        """Wall seconds until the pacer admits more (None: nothing waits; 0 on a lockstep clock, whose `pump`
        pushes device time). On a fast or manual clock, device time runs no slower than the wall clock would
        take to admit the bytes."""
        if not self._queue:
            return None
        if _lockstep(self.clock):
            return 0.0
        now = self.clock.now_us()
        due = self.pacer.due_us(now, len(self._queue))
        delay = self.clock.wall_delay_s(due)
        return delay if delay > 0 or due <= now else (due - now) / 1e6

    def backlog(self) -> int:
        return len(self._queue) + self.inner.backlog()

    def close(self) -> None:
        with self._lock:
            self._queue.clear()
        self.inner.close()


def _lockstep(clock: Clock) -> bool:
    """A fast clock without the wall-clock floor: device time moves only when pushed."""
    return bool(getattr(clock, "fast", False)) and not getattr(clock, "wall_floor", True)
