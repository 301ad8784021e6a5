"""Helpers of the live-view tests: the system Chromium's path and flags, a real-clock device on TCP."""

from __future__ import annotations

import os

from eyehil.emulator.device.build import DeviceOptions, build_device
from eyehil.emulator.device.links.base import LinkRunner
from eyehil.emulator.device.links.tcp import TcpLink

CHROMIUM = os.environ.get("EYEHIL_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
WAIT_MS = 240_000  # generous: the machine is shared; every wait is on a condition


def start_device(scene: str = "guestrin2006", port: int = 0, **options) -> LinkRunner:
    """A real-clock emulator on a TCP port (the view connects to runner.url)."""
    core = build_device(DeviceOptions(scene=scene, clock="real", **options))
    try:
        return LinkRunner(core, TcpLink(port=port)).start()
    except BaseException:
        core.close()
        raise
