"""`eyehil view URL`: a live web page of a tracker on any link the host driver opens.

    eyehil view socket://127.0.0.1:5555 --geometry g.toml          # prints view: http://127.0.0.1:8765/
    eyehil view /dev/pts/5 --open --stream features                 # opens the system browser
    eyehil view 'loop://?scene=blignaut2014' --geometry b.toml --record-video demo.mp4

The page binds to loopback unless --host says otherwise (it drives the device: do not expose it knowingly).
`add_view_options` and `start_view` are shared with ``eyehil emulate --view``.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import os
import signal
import socket
import threading
import webbrowser
from typing import TYPE_CHECKING

from eyehil.protocols.address import port_number

if TYPE_CHECKING:
    from eyehil.drivers.view.server import ViewServer

DEFAULT_PORT = 8765
#: the keys of `eyehil.drivers.view.session.STREAMS`, repeated so that the parser imports neither numpy nor OpenCV
STREAMS = ("features", "both", "frames", "detect")


class ViewListenError(OSError):
    """The page could not listen on its address; the message names the address and the reason."""


def add_view_options(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """The page's options (`prefix` "view-" for ``eyehil emulate``, whose --host/--port mean the device's)."""
    p.add_argument(f"--{prefix}host", dest="view_host", default="127.0.0.1",
                   help="address the page binds (default 127.0.0.1, loopback)")
    p.add_argument(f"--{prefix}port", dest="view_port", type=port_number, default=DEFAULT_PORT,
                   help=f"port of the page (default {DEFAULT_PORT}; 0 = any free port)")
    p.add_argument("--open", dest="view_open", action="store_true", help="open the page in the system browser")
    p.add_argument(f"--{prefix}stream", dest="view_stream", choices=[*STREAMS, "auto"], default="auto",
                   help="features, both (features and camera images), frames (images only, the host detects), "
                        "detect (both; the host detects, the device's features drawn as the reference: on the "
                        "emulator the ground truth); auto: both if the device streams images")
    p.add_argument("--record-video", metavar="FILE", help="also write the eye images with overlays (.mp4 or .png: "
                                                          "animated PNG)")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("view", help="a live web page of a tracker: camera, features, gaze and health",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("url", help="device path, socket://host:port, usbip://host:port/1-1, loop://?..., spy://URL")
    p.add_argument("--geometry", help="the tracker's geometry file (targets, calibration; eyehil emulate "
                                      "--write-geometry)")
    p.add_argument("--rate", type=int, help="sample rate, Hz (default: the device's)")
    p.add_argument("--timeout", type=float, default=2.0, help="seconds without an answer before the device counts "
                                                              "as disconnected (default 2)")
    p.add_argument("--no-start", action="store_true", help="connect without starting the stream")
    p.add_argument("--duration", type=float, help="quit after this many seconds (default: until interrupted)")
    add_view_options(p)
    p.set_defaults(func=run)


def start_view(url: str, args: argparse.Namespace, geometry_path: str | None, **session_options) -> ViewServer:
    """Start the page server on `url` with the options of `add_view_options`; print its address (and open it)."""
    from eyehil.drivers.setup_file import load_geometry
    from eyehil.drivers.view.server import ViewServer

    recorder = None
    if args.record_video:
        from eyehil.drivers.view.video import VideoRecorder

        recorder = VideoRecorder(args.record_video)
    geometry = load_geometry(geometry_path).geometry if geometry_path else None
    server = ViewServer(url, host=args.view_host, port=args.view_port, geometry=geometry, stream=args.view_stream,
                        recorder=recorder, **session_options)
    try:
        server.start()
    except OSError as exc:  # one line naming the address (exit 1), not aiohttp's "error while attempting to bind"
        reason = _bind_reason(exc)
        raise ViewListenError(f"cannot listen on view http {args.view_host}:{args.view_port}: "
                              f"{reason[:1].lower()}{reason[1:]}") from exc
    print(f"view: {server.address}", flush=True)
    if args.view_open:
        webbrowser.open(server.address)
    return server


def _bind_reason(exc: OSError) -> str:
    """Why a bind failed, in the system's words (aiohttp puts the address into `strerror` too)."""
    if not isinstance(exc, socket.gaierror) and exc.errno in errno.errorcode:
        return os.strerror(exc.errno)
    return exc.strerror or str(exc)


def close_view(server: ViewServer) -> None:
    """Stop the page and finish the video, if any."""
    recorder = server.session_options.get("recorder")
    server.close()
    if recorder is not None:
        print(f"video: {recorder.close()} ({recorder.frames} frames)", flush=True)


def run(args: argparse.Namespace) -> int:
    from eyehil.drivers.errors import TrackerError
    from eyehil.stopping import wait_for_stop

    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:  # whatever happens, the caller's SIGTERM handler comes back (a process forked later inherits ours)
        try:
            server = start_view(args.url, args, args.geometry, rate_hz=args.rate, timeout=args.timeout,
                                autostart=not args.no_start)
        except TrackerError as exc:
            print(f"eyehil view: {type(exc).__name__}: {exc}")
            return 1
        try:
            print(f"eyehil view: {args.url}; Ctrl-C stops", flush=True)
            with contextlib.suppress(KeyboardInterrupt):
                wait_for_stop(stop, args.duration)
        finally:
            close_view(server)
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0
