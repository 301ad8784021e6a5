"""The server against USB/IP clients we did not write: the Linux `usbip` tool and pyusb's USB/IP backend.

Each test skips, with its reason, when its client is not installed here:
- `usbip list -r` (Debian package `usbip`) needs only the network;
- `usbip attach` needs the vhci-hcd kernel module as well (and root); then /dev/ttyACM* is a real tty;
- pyusb + pyusb-usbip-backend (the `usb` extra) drive the device through the pyusb API.
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest
import serial
from usbip_helpers import Collector

from eyehil.emulator.device.links.usbip.server import UsbipCdcServer

USBIP = shutil.which("usbip", path=os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"]))
needs_usbip = pytest.mark.skipif(USBIP is None, reason="the usbip tool is not installed (apt-get install usbip)")


def usbip(server: UsbipCdcServer, *args: str) -> subprocess.CompletedProcess[str]:
    assert USBIP is not None
    command = [USBIP, "--tcp-port", str(server.port), *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=30, check=False)


@needs_usbip
def test_usbip_list_remote_shows_the_device(server: UsbipCdcServer) -> None:
    result = usbip(server, "list", "-r", "127.0.0.1")
    assert result.returncode == 0, result.stderr
    assert re.search(r"1-1: .*\(1209:0001\)", result.stdout), result.stdout
    assert "(02/02/00)" in result.stdout and "(0a/00/00)" in result.stdout  # the ACM and data interfaces


def _vhci_missing() -> str | None:
    if USBIP is None:
        return "the usbip tool is not installed"
    if not glob.glob("/sys/devices/platform/vhci_hcd*"):
        return "the vhci-hcd kernel module is not loaded (sudo modprobe vhci-hcd)"
    return None if os.geteuid() == 0 else "usbip attach needs root"


def _wait_tty(timeout: float = 20.0) -> str | None:
    """The /dev/ttyACM* whose USB device is 1209:0001, once the kernel has created it."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for tty in glob.glob("/sys/class/tty/ttyACM*"):
            usb_device = Path(tty, "device").resolve().parent
            ids = [(usb_device / name).read_text().strip() for name in ("idVendor", "idProduct")
                   if (usb_device / name).exists()]
            if ids == ["1209", "0001"] and os.path.exists(f"/dev/{Path(tty).name}"):
                return f"/dev/{Path(tty).name}"
        time.sleep(0.1)  # waiting for udev, not for one of our threads
    return None


def _vhci_port(server: UsbipCdcServer) -> str | None:
    listing = usbip(server, "port").stdout
    for block in re.split(r"\n(?=Port \d+:)", listing):
        number = re.match(r"\s*Port (\d+):", block)
        if number and f":{server.port}/1-1" in block:
            return number.group(1)
    return None


@pytest.mark.skipif(_vhci_missing() is not None, reason=str(_vhci_missing()))
def test_kernel_attach_gives_a_working_tty(server: UsbipCdcServer, collector: Collector) -> None:
    result = usbip(server, "attach", "-r", "127.0.0.1", "-b", "1-1")
    assert result.returncode == 0, result.stderr
    try:
        device = _wait_tty()
        assert device is not None, "no /dev/ttyACM* for 1209:0001 appeared"
        with serial.Serial(device, 115200, timeout=5) as tty:
            tty.write(b"over the kernel")
            assert collector.wait_for(15) == b"over the kernel"
            server.send(b"and back")
            assert tty.read(8) == b"and back"
    finally:
        port = _vhci_port(server)
        if port is not None:
            usbip(server, "detach", "-p", port)
    assert server.wait_attached(10.0, attached=False)


def _pyusb_backend() -> tuple[object, object] | str:
    """(usb.core, usbip_backend.get_backend), or why they cannot be used."""
    try:
        import usb.core
        from usbip_backend import get_backend
    except Exception as exc:  # missing, or broken on import: either way a skip with its reason
        return f"pyusb-usbip-backend unavailable ({type(exc).__name__}: {exc}); pip install -e '.[usb]'"
    return usb.core, get_backend


@pytest.mark.skipif(isinstance(_pyusb_backend(), str), reason=str(_pyusb_backend()))
def test_pyusb_through_the_usbip_backend(server: UsbipCdcServer, collector: Collector) -> None:
    import usb.util
    from usbip_backend import get_backend

    backend = get_backend("127.0.0.1", server.port, timeout=5.0)
    try:
        device = usb.core.find(idVendor=0x1209, idProduct=0x0001, backend=backend)
        assert device is not None
        device.set_configuration()
        # the backend builds the device descriptor from the devlist record (string indices 0): ask for 2
        assert usb.util.get_string(device, 2) == "eyehil virtual eye tracker"
        device.ctrl_transfer(0x21, 0x20, 0, 0, bytes.fromhex("00100e00000008"))  # SET_LINE_CODING 921600 8N1
        device.ctrl_transfer(0x21, 0x22, 0x0003, 0)  # SET_CONTROL_LINE_STATE DTR | RTS
        assert server.line_coding.baudrate == 921600 and server.dtr
        assert device.write(0x02, b"from pyusb") == 10
        assert collector.wait_for(10) == b"from pyusb"
        server.send(b"to pyusb")  # before the read: the backend waits for each URB, it never unlinks
        assert bytes(device.read(0x82, 512, timeout=5000)) == b"to pyusb"
    finally:
        for connection in backend._conns.values():  # the backend keeps its sockets until garbage collection
            connection.close()
