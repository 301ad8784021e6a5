"""`eyehil emulate`: run a virtual eye tracker on a link until interrupted.

    eyehil emulate --link pty                       # prints the pseudo-terminal's path; open it as a serial port
    eyehil emulate --link tcp --port 5555           # pyserial socket://127.0.0.1:5555
    eyehil emulate --link pty --mode iscan --rate 120
    eyehil emulate --link pty --link-rate usb-fs    # output paced to a full-speed USB CDC device (1.2 MB/s)
    eyehil emulate --link zmq [--port 50020] [--lsl]   # Pupil Core Network API (+ an LSL outlet), docs/zmq.md
    eyehil emulate --link opengaze [--port 4242] [--gaze-method guestrin]   # Gazepoint Open Gaze API, docs/opengaze.md
    eyehil emulate --scene blignaut2014 --write-geometry blignaut.toml   # the host's setup file

It prints a line ``url: <what a host opens>`` once the link is up. The simulated subject follows the host's
STIMULUS messages (`--script stimulus`, default) or loops over the scene's targets (`--script demo`).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import threading
from typing import TYPE_CHECKING

from eyehil.emulator.scene.presets_index import preset_names
from eyehil.protocols.address import port_number
from eyehil.stopping import wait_for_stop

if TYPE_CHECKING:
    from eyehil.emulator.device.build import DeviceOptions

# The parser is built without numpy, scipy or OpenCV (`eyehil emulate --help` stays fast): the device's modules
# are imported inside the functions that run it.

#: link name -> "module:class"; the class takes (host, port) keywords where they mean something.
LINKS: dict[str, str] = {
    "pty": "eyehil.emulator.device.links.pty:PtyLink",
    "tcp": "eyehil.emulator.device.links.tcp:TcpLink",
    "usbip": "eyehil.emulator.device.links.usbip.link:UsbipLink",
}
#: the interpreter's thread switch interval (s) in a process running a native link. The link's I/O thread waits in
#: select() and then for the interpreter lock, which the device's thread holds while it renders and encodes; at
#: Python's default of 5 ms the I/O thread refilled a pseudo-terminal's ~12 kB buffer late, and 320 x 240 frames
#: over a pty varied from 144 to 360 frames/s between runs (bench frames, 2 cores, 8 runs twice); at 0.1 ms,
#: 284 to 416 (docs/benchmarks.md, seventh session).
LINK_SWITCH_INTERVAL_S = 0.0001


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("emulate", help="run a virtual eye tracker on a pseudo-terminal, TCP or USB/IP link",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--link", choices=sorted([*LINKS, "zmq", "opengaze"]), default="pty", help="transport (default pty)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (tcp, usbip; default 127.0.0.1)")
    p.add_argument("--port", type=port_number, default=0, help="port (tcp default: any free port; usbip default 3240)")
    p.add_argument("--scene", default="guestrin2006", help=f"preset ({', '.join(preset_names())}) or TOML path")
    p.add_argument("--eyes", default="normative:navarro", help="published | sample:N | normative:NAME")
    p.add_argument("--eye", type=int, default=0, help="which eye of --eyes (default 0)")
    p.add_argument("--sides", choices=["right", "left", "both"], help="eyes the camera sees (default: the scene's)")
    p.add_argument("--seed", type=int, default=0, help="random seed (sampled eyes, behaviour)")
    p.add_argument("--head", default="", help="head pose, e.g. 'x=30,z=-40,yaw=5' (mm, deg)")
    p.add_argument("--script", choices=["stimulus", "demo"], default="stimulus", help="subject behaviour")
    p.add_argument("--mode", choices=["native", "iscan"], default="native", help="protocol (default native)")
    p.add_argument("--rate", type=int, help="default sample rate, Hz (ISCAN: the rate; default 250, opengaze 60)")
    p.add_argument("--clock", choices=["real", "fast"], default="real", help="real time or as fast as possible")
    p.add_argument("--speed", type=float, default=1.0, help="real clock: device seconds per wall second")
    p.add_argument("--link-rate", default="", metavar="RATE",
                   help="pace pty/tcp/usbip output to a real link: 12Mbit, 1MB, 115200baud, usb-fs, usb-hs "
                        "(docs/frames.md; default unpaced)")
    p.add_argument("--render-workers", type=int, default=0, metavar="N",
                   help="frames: render in N processes ahead of the link (default 0: on the device's thread)")
    p.add_argument("--behaviour", default="", help="e.g. 'latency=0.2,jitter=0.05,blinks=0.3' (s, deg, Hz)")
    p.add_argument("--write-geometry", metavar="FILE", help="write the host's tracker geometry (TOML) for the scene")
    p.add_argument("--lsl", action="store_true", help="zmq: also open an LSL outlet of type Gaze (needs pylsl)")
    p.add_argument("--record-dir", metavar="DIR", help="zmq: where `R` writes recording folders (never outside)")
    p.add_argument("--lsl-layout", choices=["eyehil", "pupil_relay"], default="eyehil",
                   help="zmq --lsl: eyehil's channels, or Pupil Capture's LSL relay name and channels")
    p.add_argument("--gaze-method", choices=["auto", "guestrin", "blignaut"], default="auto",
                   help="opengaze: the gaze estimator calibrated (default: by the scene's LEDs)")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until interrupted)")
    p.add_argument("--view", action="store_true", help="also serve the live web view (eyehil view) of this device")
    p.add_argument("--view-port", type=port_number, default=8765,
                   help="--view: port of the page (default 8765; 0 = any)")
    p.add_argument("--view-open", action="store_true", help="--view: open the page in the system browser")
    p.add_argument("--record-video", metavar="FILE", help="--view: also write the eye images (.mp4 or .png)")
    p.set_defaults(func=run)


def options(args: argparse.Namespace) -> DeviceOptions:
    """`DeviceOptions` from the command line."""
    from eyehil.emulator.device.build import DeviceOptions, options_from_query

    base = DeviceOptions(scene=args.scene, eyes=args.eyes, eye=args.eye, sides=args.sides or "", seed=args.seed,
                         script=args.script,
                         mode=args.mode, rate_hz=args.rate or (60 if args.link == "opengaze" else 250),
                         clock=args.clock, speed=args.speed, link_rate=args.link_rate,
                         render_workers=args.render_workers)
    query = "&".join(part for part in (args.head, args.behaviour) if part).replace(",", "&")
    return options_from_query(query, base)


def make_link(kind: str, host: str, port: int):
    """Instantiate the link class named in `LINKS` (imported only now)."""
    module, cls = LINKS[kind].split(":")
    try:
        factory = getattr(importlib.import_module(module), cls)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"link {kind!r} is not available: {LINKS[kind]} cannot be loaded ({exc})") from exc
    if kind == "pty":
        return factory()
    return factory(host=host, port=port or (3240 if kind == "usbip" else 0))


def make_runner(opts: DeviceOptions, args: argparse.Namespace):
    """A `LinkRunner` on the chosen link or, for ``--link zmq``, the Pupil Core facade (imported only then)."""
    from eyehil.emulator.device.build import build_device, paced
    from eyehil.emulator.device.links.base import LinkRunner

    if opts.link_rate and args.link in ("zmq", "opengaze"):
        raise ValueError("--link-rate paces the native links (pty, tcp, usbip)")
    if args.link == "zmq":
        from eyehil.emulator.device.pupil.server import server_for

        return server_for(opts, args.host, args.port or 50020, lsl=args.lsl, lsl_layout=args.lsl_layout,
                          record_dir=args.record_dir)
    if args.link == "opengaze":
        from eyehil.emulator.device.opengaze.server import server_for as opengaze_server

        if args.lsl:
            raise ValueError("--lsl needs --link zmq")
        return opengaze_server(opts, args.host, args.port or 4242, method=args.gaze_method)
    if args.lsl:
        raise ValueError("--lsl needs --link zmq")
    core = build_device(opts)
    try:
        return LinkRunner(core, paced(make_link(args.link, args.host, args.port), opts, core.clock))
    except BaseException:
        core.close()
        raise


class ViewBlink:
    """--view: lets the page close the simulated subject's eyes (the native protocol has no blink command, so only a
    view in this process can). The blink starts beyond the features the camera has already prepared
    (`camera.Camera.prepared_until_us`), so the runner's thread picks it up from the subject without being
    interrupted."""

    LEAD_US = 40_000

    def __init__(self, core) -> None:
        self.core = core

    def blink(self, duration_s: float) -> bool:
        """Close the eyes for `duration_s` seconds, starting in `LEAD_US`; False if too many are pending."""
        start = max(self.core.clock.now_us() + self.LEAD_US, self.core.camera.prepared_until_us + 1)
        return self.core.subject.blink(start, duration_s)


def _view_starter(args: argparse.Namespace):
    """--view: the live page is a host (eyehil.drivers.view), which the emulator does not import (DESIGN.md); the
    `eyehil` command hands its starter in (`eyehil.emulate_view.start_view`) as the default `view_starter`."""
    starter = getattr(args, "view_starter", None)
    if starter is None:
        raise ValueError("--view is served by the `eyehil` command (eyehil.emulate_view); it is not available here")
    return starter


def run(args: argparse.Namespace) -> int:
    opts = options(args)
    if args.write_geometry:
        from eyehil.emulator.device.setup_file import write_geometry
        from eyehil.emulator.scene import load_scene

        print(f"geometry: {write_geometry(load_scene(opts.scene), args.write_geometry)}", flush=True)
    stop, interrupted = threading.Event(), False
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())  # SIGTERM stops cleanly, like Ctrl-C
    interval = sys.getswitchinterval()
    if args.link in LINKS:  # the native links
        sys.setswitchinterval(LINK_SWITCH_INTERVAL_S)
    try:
        with make_runner(opts, args) as runner, contextlib.ExitStack() as view:
            print(f"url: {runner.url}", flush=True)
            if args.view:
                core = getattr(runner, "core", None)
                view.callback(*_view_starter(args)(runner.url, opts, args, None if core is None else ViewBlink(core)))
            print(f"eyehil emulate: {opts.mode} device, scene {opts.scene}, eyes {opts.eyes}[{opts.eye}], "
                  f"script {opts.script}, {opts.clock} clock; Ctrl-C stops", flush=True)
            try:
                wait_for_stop(stop, args.duration)  # in slices: the signal may land on another thread
            except KeyboardInterrupt:
                interrupted = True  # the device and its links close first, then the usual exit for Ctrl-C
    finally:
        signal.signal(signal.SIGTERM, previous)
        sys.setswitchinterval(interval)
    return 130 if interrupted else 0  # SIGTERM and --duration end normally
