"""`eyehil emulate --link opengaze` from the command line: it prints its URL and answers a GET."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

from opengaze_helpers import DEADLINE_S, LineClient

ROOT = Path(__file__).parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_emulate_link_opengaze() -> None:
    port = _free_port()
    cmd = [sys.executable, "-c", "import eyehil.cli, sys; sys.exit(eyehil.cli.main())", "emulate", "--link",
           "opengaze", "--port", str(port), "--rate", "150", "--gaze-method", "guestrin"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    try:
        line = proc.stdout.readline()
        assert line.strip() == f"url: tcp://127.0.0.1:{port}", line
        client = LineClient(port)
        try:
            client.send(b'<GET ID="CAMERA_SIZE" />\r\n<SET ID="ENABLE_SEND_COUNTER" STATE="1" />\r\n'
                        b'<SET ID="ENABLE_SEND_DATA" STATE="1" />\r\n')
            assert client.wait_for("ACK", "CAMERA_SIZE").attrs == {"ID": "CAMERA_SIZE", "WIDTH": "640",
                                                                    "HEIGHT": "480"}
            first = int(client.wait_for("REC").attrs["CNT"])
            assert int(client.wait_for("REC").attrs["CNT"]) == first + 1
        finally:
            client.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=DEADLINE_S) == 0
        proc.stdout.close()
