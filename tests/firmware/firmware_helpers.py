"""Helpers of the firmware-in-the-loop tests: build the C firmware, run it on a pseudo-terminal in front of the
Python sensor, and exchange raw bytes with a device.

`FirmwareRig` is one running firmware: its sensor (`eyehil.emulator.device.firmware_sensor`, served in this process),
the firmware process (`eyehil-firmware --pty --sensor SOCKET`, whose first stdout line is ``url: /dev/pts/N``)
and that URL, which the host driver opens. `close` stops both and checks the firmware exited cleanly.
"""

from __future__ import annotations

import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlencode

from eyehil.emulator.device.build import options_from_query
from eyehil.emulator.device.firmware_sensor import FirmwareSensor, SensorServer
from eyehil.protocols.native import DEVICE_TYPES
from eyehil.protocols.stream import NativeReceiver, Received

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ROOT / "firmware_stubs"
GOLDEN = ROOT / "tests" / "golden"
START_TIMEOUT_S = 60.0  # generous: the firmware may run under valgrind
EXIT_TIMEOUT_S = 30.0


@dataclass(frozen=True)
class FirmwareBuild:
    """The two binaries `make` builds."""

    firmware: Path
    unit_tests: Path


def build_firmware(build_dir: Path) -> FirmwareBuild:
    """Run the firmware's Makefile into `build_dir`; raise RuntimeError with the compiler's output on failure."""
    result = subprocess.run(["make", "-C", str(SOURCES), f"BUILD={build_dir}"], capture_output=True, text=True,
                            timeout=120, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"firmware build failed:\n{result.stdout}\n{result.stderr}")
    return FirmwareBuild(build_dir / "eyehil-firmware", build_dir / "test_codecs")


def compiler_missing() -> str | None:
    """Why the firmware cannot be built here, or None."""
    for tool in ("make", "cc"):
        if shutil.which(tool) is None:
            return f"no {tool} on PATH: the C firmware cannot be built"
    return None


def _read_url(process: subprocess.Popen, log: Path) -> str:
    """The ``url: PATH`` line the firmware prints once it is ready."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while (remaining := deadline - time.monotonic()) > 0:
        if select.select([process.stdout], [], [], remaining)[0]:
            line = process.stdout.readline().decode()
            if line.startswith("url: "):
                return line.split(maxsplit=1)[1].strip()
            if not line:
                break
    raise RuntimeError(f"the firmware did not start (exit {process.poll()}): {log.read_text()}")


class FirmwareRig:
    """A sensor and a firmware process joined on a Unix socket; the firmware's UART is a pseudo-terminal."""

    def __init__(self, binary: Path, *, camera: str = "features", wrapper: tuple[str, ...] = (),
                 args: tuple[str, ...] = (), **options: object) -> None:
        """Start both; `camera`: "features" (the sensor detects) or "pixels" (raw frames, the firmware extracts);
        `wrapper`: a command the firmware runs under (e.g. valgrind); `args`: more firmware arguments (e.g.
        ``("--mode", "iscan")``); `options` are
        `eyehil.emulator.device.build.options_from_query` keys (scene, eye, script ...); ``clock="fast"`` runs the
        firmware in lockstep with its host (``--clock fast``) and lets the sensor's subject wait for exact solves."""
        self._dir = Path(tempfile.mkdtemp(prefix="eyehil-fw-"))  # short: socket paths are limited to 107 bytes
        self.log = self._dir / "firmware.log"
        self.sensor = FirmwareSensor.from_options(options_from_query(urlencode(options)), frames=camera == "pixels")
        self.server = SensorServer(self.sensor, self._dir / "sensor.sock").start()
        self.process: subprocess.Popen | None = None
        try:
            with self.log.open("wb") as log:
                self.process = subprocess.Popen([*wrapper, str(binary), "--pty", "--sensor", self.server.path,
                                                 "--camera", camera, "--clock", str(options.get("clock", "real")),
                                                 *args], stdout=subprocess.PIPE, stderr=log)
            self.url = _read_url(self.process, self.log)
        except BaseException:
            self.close(check=False)
            raise

    def close(self, check: bool = True) -> int | None:
        """SIGTERM the firmware, wait for it, close the sensor; with `check`, assert a clean exit (status 0)."""
        status = None
        if self.process is not None:
            self.process.terminate()
            try:
                status = self.process.wait(EXIT_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
            self.process.stdout.close()
        self.server.close()
        shutil.rmtree(self._dir, ignore_errors=True)
        if check:
            assert status == 0, f"the firmware did not exit cleanly (status {status})"
        return status


def exchange_raw(link, data: bytes, until_type: int, timeout_s: float = 5.0) -> list[Received]:
    """Write `data` to a raw link; return every device message decoded until one of type `until_type` (included).

    Faults on the way back would fail the caller's comparison, so only decoded messages are returned.
    """
    receiver = NativeReceiver(accept=DEVICE_TYPES)
    link.write(data)
    received: list[Received] = []
    deadline = time.monotonic() + timeout_s
    while (remaining := deadline - time.monotonic()) > 0:
        select.select([link.fileno()], [], [], remaining)
        received += [e for e in receiver.feed(link.read(65536)) if isinstance(e, Received)]
        if received and received[-1].header.msg_type == until_type:
            return received
    raise TimeoutError(f"no message of type 0x{until_type:02X} within {timeout_s} s: {received}")
