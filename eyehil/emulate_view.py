"""`eyehil emulate --view`: the live page (a host, `eyehil.drivers.view`) beside the device, in one process.

The emulator does not import the host (DESIGN.md), so the `eyehil` command joins the two here and hands
`start_view` to `eyehil emulate` as its `view_starter`.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from eyehil.drivers.view.cli import close_view
from eyehil.drivers.view.cli import start_view as serve
from eyehil.emulator.device.build import DeviceOptions
from eyehil.emulator.device.setup_file import write_geometry
from eyehil.emulator.scene import load_scene


def start_view(url: str, opts: DeviceOptions, args: argparse.Namespace, blink: Any = None) -> tuple:
    """The live page on the device at `url`, a host like any other; return (close, server) for an ExitStack.

    `blink` (optional) lets the page close the subject's eyes, which only a view in the device's process can do.
    """
    if args.link == "zmq" or opts.mode != "native":
        raise ValueError("--view needs a native-protocol device (--link pty|tcp|usbip, --mode native)")
    view_args = argparse.Namespace(view_host="127.0.0.1", view_port=args.view_port, view_open=args.view_open,
                                   view_stream="auto", record_video=args.record_video)
    if args.write_geometry:
        return close_view, serve(url, view_args, str(args.write_geometry), oracle=blink)
    with tempfile.TemporaryDirectory(prefix="eyehil-view-") as folder:  # the page reads the file once, at start
        geometry = write_geometry(load_scene(opts.scene), Path(folder) / "geometry.toml")
        return close_view, serve(url, view_args, str(geometry), oracle=blink)
