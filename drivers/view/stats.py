"""Health figures of the live stream: sample rate, latency percentiles, confidence over the last seconds.

Host times are microseconds of ``time.monotonic_ns()`` (`eyehil.drivers.wire.host_now_us`); latency is the
sample's arrival minus its exposure's mid-time, both on the host clock (device time mapped with
`eyehil.drivers.client.ClockSync`), in milliseconds. Everything is kept in bounded deques.
"""

from __future__ import annotations

from collections import deque

import numpy as np

RATE_WINDOW_US = 1_000_000
LATENCY_SAMPLES = 2_000
HISTORY_S = 10.0
MAX_RATE_SAMPLES = 20_000  # bounds the rate window (a 2 kHz device for 10 s)


class StreamStats:
    """Rolling rate (Hz over the last second), latency p50/p99 (ms) and a confidence history (10 s)."""

    def __init__(self, history_s: float = HISTORY_S) -> None:
        self.history_us = round(history_s * 1e6)
        self._arrivals: deque[int] = deque(maxlen=MAX_RATE_SAMPLES)
        self._latency_ms: deque[float] = deque(maxlen=LATENCY_SAMPLES)

    def add(self, host_us: int, latency_ms: float | None) -> None:
        """One sample arrived at `host_us`, `latency_ms` after its exposure (None if unknown)."""
        self._arrivals.append(host_us)
        if latency_ms is not None and np.isfinite(latency_ms):
            self._latency_ms.append(latency_ms)

    def rate_hz(self, now_us: int) -> float:
        """Samples per second over the last second ending at `now_us`."""
        while self._arrivals and self._arrivals[0] < now_us - RATE_WINDOW_US:
            self._arrivals.popleft()
        return len(self._arrivals) * 1e6 / RATE_WINDOW_US

    def latency_ms(self) -> tuple[float | None, float | None]:
        """(p50, p99) ms of the last `LATENCY_SAMPLES` latencies, or (None, None)."""
        if not self._latency_ms:
            return None, None
        p50, p99 = np.percentile(np.fromiter(self._latency_ms, float), [50, 99])
        return float(p50), float(p99)

    def reset(self) -> None:
        """Forget everything (a new connection)."""
        self._arrivals.clear()
        self._latency_ms.clear()
