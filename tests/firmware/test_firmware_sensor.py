"""The Python side of the firmware's sensor link (`eyehil.emulator.device.firmware_sensor`), without a C compiler: the
line protocol, the socket server and its command line."""

from __future__ import annotations

import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from eyehil.emulator.device.build import DeviceOptions
from eyehil.emulator.device.firmware_sensor import FirmwareSensor, SensorServer


@pytest.fixture
def sensor():
    s = FirmwareSensor.from_options(DeviceOptions(scene="blignaut2014", script="demo"))
    yield s
    s.close()


def test_requests_and_replies(sensor: FirmwareSensor) -> None:
    assert sensor.handle("HELLO 1") == "INFO 1600 1200 1 3 1"
    assert sensor.handle("EXPOSE 2000").startswith("ERR EXPOSE: not started")
    assert sensor.handle("LEDS 2").startswith("ERR LEDS")  # the scene has one LED
    assert [sensor.handle(r) for r in ("LEDS 1", "START 500 2 0 0 0 0")] == ["OK", "OK"]
    fields = sensor.handle("EXPOSE 2000").split()
    assert fields[:4] == ["FEATURES", "1", "1", "1"]  # one eye record: the left eye, DETECTED
    assert len(fields) == 2 + 9 + 4 and fields[10] == "1"  # its ellipse, one glint
    for bad in ("", "NOPE", "START 500", "EXPOSE soon", "STIMULUS 1 2 3", "STOP now"):
        assert sensor.handle(bad).startswith("ERR"), bad
    assert sensor.handle("STOP") == "OK" and sensor.handle("EXPOSE 4000").startswith("ERR")


def test_exposed_values_are_the_detectors_read_back_exactly(sensor: FirmwareSensor) -> None:
    sensor.handle("LEDS 1")
    sensor.handle("START 500 3 0 0 0 0")
    line = sensor.handle("EXPOSE 123456").split()
    expected = sensor.features(np.array([123456]))
    right = [float(v) for v in line[4:10]]
    assert right == [*expected["centre"][0, 0], *expected["axes"][0, 0], expected["angle_deg"][0, 0], 1.0]


def test_stimulus_moves_the_subject_or_is_refused(sensor: FirmwareSensor) -> None:
    assert sensor.handle("STIMULUS 1000 7 100.5 50.25 1") == "OK"
    assert sensor.handle("STIMULUS 2000 8 nan 50 1") == "ERR STIMULUS: position not finite"
    assert sensor.handle("STIMULUS 2000 9 1e6 50 1").startswith("ERR STIMULUS: position too far")
    assert sensor.stimuli == [(1000, 7, 100.5, 50.25, 1)]
    assert sensor.subject.script is None  # the demo script gave way to the host's target


def _ask(conn: socket.socket, line: str, timeout_s: float = 5.0) -> str:
    """Send one request line; return the reply line."""
    conn.sendall(line.encode() + b"\n")
    reply = b""
    deadline = time.monotonic() + timeout_s
    while not reply.endswith(b"\n") and (remaining := deadline - time.monotonic()) > 0:
        if select.select([conn], [], [], remaining)[0]:
            reply += conn.recv(4096)
    return reply.decode().strip()


def test_server_answers_one_connection_after_another(sensor: FirmwareSensor) -> None:
    with tempfile.TemporaryDirectory(prefix="eyehil-") as tmp, SensorServer(sensor, Path(tmp) / "s.sock") as server:
        for _ in range(2):
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
                conn.connect(server.path)
                assert _ask(conn, "HELLO 1").startswith("INFO 1600 1200")
                assert _ask(conn, "BOGUS").startswith("ERR")
        assert server.connections == 2 and server.failure is None
    assert not Path(server.path).exists()


def test_command_line_serves_until_sigterm() -> None:
    with tempfile.TemporaryDirectory(prefix="eyehil-") as tmp:
        path = Path(tmp) / "s.sock"
        process = subprocess.Popen([sys.executable, "-m", "eyehil.emulator.device.firmware_sensor", "--socket", str(path),
                                    "--scene", "guestrin2006"], stdout=subprocess.PIPE, text=True)
        try:
            assert select.select([process.stdout], [], [], 30)[0]
            assert process.stdout.readline().strip() == f"sensor: {path}"
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
                conn.connect(str(path))
                assert _ask(conn, "HELLO 1") == "INFO 640 480 2 1 1"
            process.send_signal(signal.SIGTERM)
            assert process.wait(10) == 0
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
            process.stdout.close()
        assert not path.exists()
