"""`eyehil emulate --view`: the device and its page in one process, the page a host on the device's URL."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_emulate_view_serves_the_page_of_its_device_and_stops_cleanly(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-m", "eyehil.cli", "emulate", "--link", "tcp", "--view", "--view-port",
                             "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    try:
        lines = []
        while not any(line.startswith("view: ") for line in lines):
            line = proc.stdout.readline()
            assert line, f"eyehil emulate --view ended: {lines} {proc.stderr.read()}"
            lines.append(line)
        device = next(line.split()[1] for line in lines if line.startswith("url: "))
        address = next(line.split()[1] for line in lines if line.startswith("view: "))
        assert address.startswith("http://127.0.0.1:") and device.startswith("socket://127.0.0.1:")
        page = urllib.request.urlopen(address, timeout=30).read().decode()
        assert "eyehil live view" in page and "/static/view.js" in page
        deadline = time.monotonic() + 120  # generous: a real process on a shared machine
        stats = {}
        while time.monotonic() < deadline and stats.get("host", {}).get("samples", 0) == 0:
            stats = json.loads(urllib.request.urlopen(address + "stats", timeout=30).read())
        assert stats["host"]["samples"] > 0 and stats["session"]["reconnects"] == 1
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # the page's geometry file (and LSL's configuration, if any) are gone
