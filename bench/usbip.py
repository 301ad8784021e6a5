"""Benchmark: the USB link (USB/IP over loopback TCP) between the emulator's server and our host client.

Throughput both ways with 16 MiB (host -> device: `write` in 1 MiB calls until `on_data` has it all;
device -> host: one `send`, then `read` until everything arrived), best of `repeats`; round-trip latency
of a 74-byte message (one FEATURES frame on the wire: one eye, two glints, see docs/protocol.md): host
`write`, the device echoes it from `on_data`, host `read`, 1000 times per repeat, percentiles over all.
For scale (docs: reference link capacities): USB 2.0 high-speed bulk about 40 MB/s, full-speed CDC about 1 MB/s.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from eyehil.drivers.links.usbip import UsbipSerial
from eyehil.emulator.device.links.usbip.server import UsbipCdcServer

SIZE = 16 * 1024 * 1024
MESSAGE = bytes(range(74))
ROUND_TRIPS = 1000


class _Device:
    """`on_data` for the benchmark: counts bytes, or echoes them back when `echo` is set."""

    def __init__(self) -> None:
        self.server: UsbipCdcServer | None = None
        self.echo = False
        self.received = 0
        self._cond = threading.Condition()

    def __call__(self, data: bytes) -> None:
        if self.echo and self.server:
            self.server.send(data)
            return
        with self._cond:
            self.received += len(data)
            self._cond.notify_all()

    def wait_for(self, n: int, timeout: float = 60.0) -> None:
        with self._cond:
            if not self._cond.wait_for(lambda: self.received >= n, timeout):
                raise TimeoutError(f"device received {self.received} of {n} bytes")


def _host_to_device(device: _Device, port: UsbipSerial, payload: bytes) -> float:
    device.received = 0
    start = time.perf_counter()
    for i in range(0, len(payload), 1 << 20):
        port.write(payload[i: i + (1 << 20)])
    device.wait_for(len(payload))
    return time.perf_counter() - start


def _device_to_host(server: UsbipCdcServer, port: UsbipSerial, payload: bytes) -> float:
    start = time.perf_counter()
    assert server.send(payload) == len(payload)
    got = 0
    while got < len(payload):
        chunk = port.read(len(payload) - got)
        if not chunk:
            raise TimeoutError(f"host received {got} of {len(payload)} bytes")
        got += len(chunk)
    return time.perf_counter() - start


def _round_trips(port: UsbipSerial, n: int) -> list[float]:
    times = []
    for _ in range(n):
        start = time.perf_counter()
        port.write(MESSAGE)
        if port.read(len(MESSAGE)) != MESSAGE:
            raise RuntimeError("echo mismatch")
        times.append(time.perf_counter() - start)
    return times


def run(repeats: int = 3) -> dict[str, float]:
    """Best-of-`repeats` throughput (MB/s, 1 MB = 1e6 bytes) and round-trip percentiles (us)."""
    payload = np.random.default_rng(0).integers(0, 256, SIZE, dtype=np.uint8).tobytes()
    device = _Device()
    with UsbipCdcServer(device, max_buffer=2 * SIZE) as server:
        device.server = server
        port = UsbipSerial("127.0.0.1", server.port, timeout=30.0)
        try:
            up = min(_host_to_device(device, port, payload) for _ in range(repeats))
            down = min(_device_to_host(server, port, payload) for _ in range(repeats))
            device.echo = True
            rtt = np.array([t for _ in range(repeats) for t in _round_trips(port, ROUND_TRIPS)]) * 1e6
        finally:
            port.close()
    return {"host_to_device_MBps": SIZE / up / 1e6, "device_to_host_MBps": SIZE / down / 1e6,
            "rtt_p50_us": float(np.percentile(rtt, 50)), "rtt_p99_us": float(np.percentile(rtt, 99)),
            "round_trips": float(len(rtt))}


def report(results: dict[str, float]) -> str:
    return (
        f"USB/IP link (CDC-ACM over loopback TCP): host->device {results['host_to_device_MBps']:.0f} MB/s, "
        f"device->host {results['device_to_host_MBps']:.0f} MB/s (16 MiB); 74-byte round trip "
        f"p50 {results['rtt_p50_us']:.0f} us, p99 {results['rtt_p99_us']:.0f} us "
        f"({results['round_trips']:.0f} round trips); USB 2.0 high-speed bulk carries about 40 MB/s"
    )
