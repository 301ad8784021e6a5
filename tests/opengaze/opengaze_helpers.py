"""Helpers of the Open Gaze tests: start a server, a raw line client, visual angles between screen points."""

from __future__ import annotations

import socket
import time

import numpy as np

from eyehil.emulator.device.build import DeviceOptions
from eyehil.emulator.device.opengaze.samples import fraction_to_screen
from eyehil.emulator.device.opengaze.server import OpenGazeServer, server_for
from eyehil.emulator.scene import Scene
from eyehil.protocols.opengaze import Record, parse_record

DEADLINE_S = 30.0  # generous: a real process on a busy machine


def start_server(scene: str = "guestrin2006", sides: str = "both", rate_hz: int = 60, **device: object
                 ) -> OpenGazeServer:
    """A started server on a free port of 127.0.0.1 (real clock)."""
    options = DeviceOptions(scene=scene, sides=sides, rate_hz=rate_hz)
    return server_for(options, port=0, **device).start()


def angle_deg(scene: Scene, a: tuple[float, float], b: tuple[float, float]) -> float:
    """Visual angle (deg) between two Open Gaze screen points (fractions), seen from the head's origin
    (midway between the eyes)."""
    pa, pb = (scene.screen.centre + np.append(fraction_to_screen(scene.screen.size, np.array(p, float)), 0.0)
              for p in (a, b))
    cos = float(pa @ pb / (np.linalg.norm(pa) * np.linalg.norm(pb)))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


class LineClient:
    """A raw TCP client: send bytes, read records (REC skipped unless asked)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        self._buffer = b""
        self._queue: list[Record] = []

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def records(self) -> list[Record]:
        """Whatever complete records have arrived (waits for at least one chunk)."""
        chunk = self.sock.recv(65536)
        if not chunk:
            raise ConnectionError("closed by the server")
        self._buffer += chunk
        *lines, self._buffer = self._buffer.split(b"\r\n")
        return [parse_record(line, max_attributes=1000, max_bytes=1 << 16) for line in lines if line]

    def wait_for(self, tag: str, rid: str = "", deadline_s: float = DEADLINE_S) -> Record:
        """The next record with `tag` (and ID `rid`, if given); records before it are consumed."""
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            while self._queue:
                r = self._queue.pop(0)
                if r.tag == tag and (not rid or r.id == rid):
                    return r
            self._queue = self.records()
        raise TimeoutError(f"no {tag} {rid} within {deadline_s} s")

    def close(self) -> None:
        self.sock.close()
