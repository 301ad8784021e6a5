"""Host subcommands: `eyehil info | stream | calibrate | record URL`.

URL: a device path (/dev/ttyACM0, a pseudo-terminal), socket://host:port, loop://?options (an
in-process emulator), spy://<URL> (hex dump), usbip://host:port (see `eyehil.drivers.links`).

    eyehil info /dev/pts/5
    eyehil stream socket://127.0.0.1:5555 --rate 500 --duration 2
    eyehil stream /dev/pts/5 --frames --save frames/     # frames only: the host detects; PNGs of the printed ones
    eyehil calibrate /dev/pts/5 --method guestrin --geometry guestrin2006.toml [--frames]
    eyehil record /dev/pts/5 -o run.jsonl --duration 10 --targets 3x3 --geometry guestrin2006.toml
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from eyehil.protocols.enums import Eye, EyeSelect, StreamSelect

if TYPE_CHECKING:
    import numpy as np

    from eyehil.drivers.client import Tracker
    from eyehil.drivers.frames import FrameReader

# The parsers are built without numpy, scipy or OpenCV (`eyehil info --help` stays fast): the modules that need
# them are imported inside the functions that run a subcommand.

EYES = {"right": EyeSelect.RIGHT, "left": EyeSelect.LEFT, "both": EyeSelect.BOTH}
#: `eyehil.drivers.calibration.METHODS`, repeated here so that the parser does not import the estimators (scipy)
METHODS = ("guestrin", "blignaut")


def _common() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("url", help="device path, socket://host:port, loop://?..., spy://URL, usbip://host:port")
    common.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for anything (default 2)")
    common.add_argument("--fault", metavar="SPEC", help="inject faults into what the device sends, e.g. "
                        "drop=0.01,corrupt=0.001,delay=5ms,duplicate=0.005,reorder=0.005 (eyehil.drivers.links.fault)")
    return common


def _stream_options() -> argparse.ArgumentParser:
    opts = argparse.ArgumentParser(add_help=False)
    opts.add_argument("--rate", type=int, help="sample rate, Hz (default: the device's)")
    opts.add_argument("--eyes", choices=sorted(EYES), help="eyes to stream (default: all the device has)")
    opts.add_argument("--duration", type=float, default=2.0, help="seconds of device time (default 2)")
    return opts


def register_info(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", parents=[_common()], help="handshake and print DEVICE_INFO and STATUS")
    p.set_defaults(func=run_info)


def register_stream(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("stream", parents=[_common(), _stream_options()], help="stream samples and print them")
    p.add_argument("--every", type=int, default=0, help="print every Nth sample (default: about 10 per second)")
    p.add_argument("--frames", action="store_true", help="stream camera images only; the host detects the features")
    p.add_argument("--save", metavar="DIR", help="with --frames: write the printed samples' images as PNG files")
    p.add_argument("--geometry", help="with --frames: the geometry file, to match glints to LEDs by position")
    p.set_defaults(func=run_stream)


def register_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", parents=[_common()], help="calibrate gaze through the device, validate, stream")
    p.add_argument("--method", choices=METHODS, required=True)
    p.add_argument("--geometry", required=True, help="the tracker's geometry file (eyehil emulate --write-geometry)")
    p.add_argument("--model", type=int, default=3, help="blignaut: published model 1..8 (default 3)")
    p.add_argument("--rate", type=int, help="sample rate, Hz (default: the device's)")
    p.add_argument("--settle", type=float, default=0.5, help="s discarded after each target appears (default 0.5)")
    p.add_argument("--collect", type=float, default=0.2, help="s averaged per target (default 0.2)")
    p.add_argument("--gaze-seconds", type=float, default=1.0, help="then stream gaze this long (default 1)")
    p.add_argument("--frames", action="store_true", help="stream camera images only; the host detects the features")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run_calibrate)


def register_record(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", parents=[_common(), _stream_options()], help="record samples (docs/recording.md)")
    p.add_argument("-o", "--output", required=True, help="output file (.jsonl)")
    p.add_argument("--targets", help="show a grid of targets while recording, e.g. 3x3 (needs --geometry)")
    p.add_argument("--geometry", help="the tracker's geometry file (for --targets)")
    p.add_argument("--dwell", type=float, default=1.0, help="s per target (default 1)")
    p.set_defaults(func=run_record)


def register(sub: argparse._SubParsersAction) -> None:
    """Add every host subcommand (eyehil.cli registers them one by one)."""
    for add in (register_info, register_stream, register_calibrate, register_record):
        add(sub)


def _reported(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Print a `TrackerError` as one line on stderr and return 1 (the dispatcher handles ValueError)."""
    @functools.wraps(run)
    def wrapper(args: argparse.Namespace) -> int:
        from eyehil.drivers.errors import TrackerError

        try:
            return run(args)
        except TrackerError as exc:
            print(f"eyehil {args.command}: {type(exc).__name__}: {exc}", file=sys.stderr)
            return 1
    return wrapper


def _open(args: argparse.Namespace) -> Tracker:
    from eyehil.drivers.client import Tracker, open_tracker
    from eyehil.drivers.links import open_link
    from eyehil.drivers.links.fault import wrap

    if not getattr(args, "fault", None):
        return open_tracker(args.url, timeout=args.timeout)
    link = wrap(open_link(args.url, timeout=0.0), args.fault)
    try:
        return Tracker(link, url=args.url, timeout=args.timeout)
    except BaseException:
        link.close()
        raise


@_reported
def run_info(args: argparse.Namespace) -> int:
    with _open(args) as tracker:
        info, status, sync = tracker.info, tracker.status(), tracker.sync_clock()
    print(f"{info.model} {info.firmware_version}, protocol {info.protocol_min}..{info.protocol_max}")
    print(f"  camera {info.camera_width} x {info.camera_height} px, {info.led_count} LED(s), rate "
          f"{info.sample_rate_hz} Hz ({info.min_rate_hz}..{info.max_rate_hz}), max payload {info.max_payload}")
    print(f"  capabilities {', '.join(c.name.lower() for c in type(info.capabilities) if c in info.capabilities)}")
    print(f"  clock: device - host = {sync.offset_us / 1e6:+.6f} s, round trip {sync.rtt_us:.0f} us")
    print("  status " + ", ".join(f"{k} {int(v)}" for k, v in asdict(status).items() if v))
    return 0


def _start(tracker: Tracker, args: argparse.Namespace) -> Tracker | FrameReader:
    """CONFIGURE and START; return what to read samples from (the tracker, or a FrameReader with --frames)."""
    from eyehil.drivers.frames import reader_for
    from eyehil.drivers.setup_file import load_geometry

    frames = getattr(args, "frames", False)
    tracker.configure(rate_hz=args.rate, eyes=EYES[args.eyes] if args.eyes else None,
                      stream=StreamSelect.FRAMES if frames else StreamSelect.FEATURES)
    geometry = getattr(args, "geometry", None) if frames else None
    reader = reader_for(tracker, frames, load_geometry(geometry).geometry.leds[:, :2] if geometry else None)
    tracker.start()
    return reader


def _describe(sample) -> str:
    parts = [f"#{sample.frame_id} t={sample.device_us / 1e6:.4f}s"]
    for e in sample.eyes:
        glints = " ".join(f"({g.x:.2f},{g.y:.2f})" if g.flags else "(-)" for g in e.glints)
        pupil = f"({e.centre_x:.2f},{e.centre_y:.2f})" if e.flags & 1 else "(-)"
        parts.append(f"{Eye(e.eye).name.lower()} pupil {pupil} glints {glints} flags {int(e.flags)}")
    return "  ".join(parts)


@_reported
def run_stream(args: argparse.Namespace) -> int:
    with _open(args) as tracker:
        reader = _start(tracker, args)
        every = args.every or max(1, tracker.info.sample_rate_hz // 10)
        start, n = None, 0
        for sample in reader.samples():
            start = sample.device_us if start is None else start
            if n % every == 0:
                print(_describe(sample))
                _save(reader, args.save)
            n += 1
            if sample.device_us - start >= args.duration * 1e6:
                break
        tracker.stop()
        counters = ", ".join(f"{k} {v}" for k, v in tracker.stats.as_dict().items() if v)
        print(f"{n} samples; host counters: {counters}")
    return 0


def _save(reader: Tracker | FrameReader, directory: str | None) -> None:
    """Write the images of the reader's last sample as DIR/frame_<frame id>_<eye>.png."""
    import cv2

    from eyehil.drivers.frames import FrameReader

    if not directory or not isinstance(reader, FrameReader):
        return
    Path(directory).mkdir(parents=True, exist_ok=True)
    for got in reader.last_images:
        name = f"frame_{got.image.frame_id:010d}_{Eye(got.image.eye).name.lower()}.png"
        cv2.imwrite(str(Path(directory) / name), got.image.pixels)


@_reported
def run_calibrate(args: argparse.Namespace) -> int:
    from eyehil.drivers.calibration import Plan, calibrate
    from eyehil.drivers.frames import reader_for
    from eyehil.drivers.setup_file import load_geometry

    geometry = load_geometry(args.geometry).geometry
    with _open(args) as tracker:
        plan = Plan.default(geometry.screen, settle_s=args.settle, collect_s=args.collect)
        result = calibrate(tracker, geometry, args.method, plan, model=args.model, rate_hz=args.rate,
                           frames=args.frames, progress=None if args.quiet else _target_progress)
        params = ", ".join(f"{k} {_readable(k, v)}" for k, v in result.calibration.params.items()
                           if k != "coefficients")
        print(f"{args.method}: calibrated on {len(plan.calibration_mm)} targets; {params}")
        for target, est, err in zip(plan.validation_mm, result.estimates_mm, result.errors_deg, strict=True):
            print(f"  validation target ({target[0]:+7.1f}, {target[1]:+7.1f}) mm -> ({est[0]:+7.1f}, {est[1]:+7.1f})"
                  f" mm, error {err:.3f} deg")
        print(f"  mean validation error {result.mean_error_deg:.3f} deg")
        _stream_gaze(tracker, result, args.gaze_seconds, reader_for(tracker, args.frames, geometry.leds[:, :2]))
    return 0


def _readable(name: str, value: object) -> str:
    """A fitted parameter for a person: a Blignaut form as its terms, numbers to 4 significant digits, mappings
    and lists unpacked."""
    if name.endswith("_form"):
        from eyehil.drivers.gaze.forms import describe

        return f"({describe(value)})"  # type: ignore[arg-type]
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return "(" + ", ".join(f"{k} {_readable(k, v)}" for k, v in value.items()) + ")"
    if isinstance(value, list | tuple):
        return "/".join(_readable(name, v) for v in value)
    return str(getattr(value, "tolist", lambda: value)())


def _target_progress(done: int, total: int) -> None:
    """One stderr line per target (a calibration takes a second or more per target)."""
    print(f"eyehil calibrate: target {done}/{total}", file=sys.stderr, flush=True)


def _stream_gaze(tracker: Tracker, result, seconds: float, reader: Tracker | FrameReader) -> None:
    """Stream gaze for `seconds` of device time (samples from `reader`), printing about ten estimates per second."""
    from eyehil.drivers.calibration import gaze
    from eyehil.drivers.frames import FrameReader

    if seconds <= 0:
        return
    tracker.start()
    every, start = max(1, tracker.info.sample_rate_hz // 10), None
    frames = reader if isinstance(reader, FrameReader) else None
    for i, (sample, xy) in enumerate(gaze(tracker, result, reader=frames)):
        start = sample.device_us if start is None else start
        if i % every == 0:
            print(f"  gaze t={sample.device_us / 1e6:.3f}s ({xy[0]:+7.1f}, {xy[1]:+7.1f}) mm")
        if sample.device_us - start >= seconds * 1e6:
            break
    tracker.stop()


@_reported
def run_record(args: argparse.Namespace) -> int:
    from eyehil.drivers.recording import Recorder

    with _open(args) as tracker:
        sync = tracker.sync_clock()
        _start(tracker, args)
        with Recorder(args.output, tracker, clock_sync=sync) as rec:
            targets = _targets(args)
            first, shown, t_end = None, -1, None
            for sample in tracker.samples():
                first = sample.device_us if first is None else first
                elapsed = (sample.device_us - first) / 1e6
                if targets is not None and int(elapsed // args.dwell) > shown and shown + 1 < len(targets):
                    shown += 1
                    x, y = (float(v) for v in targets[shown])
                    rec.target(shown, x, y, device_us=tracker.stimulus(shown, x, y), label=f"grid {shown}")
                rec.write(sample)
                t_end = elapsed
                if elapsed >= args.duration:
                    break
            tracker.stop()
            rec.close(tracker.stats.as_dict(), tracker.status())
        print(f"{rec.samples} samples over {t_end or 0:.2f} s written to {args.output}")
    return 0


def _targets(args: argparse.Namespace) -> np.ndarray | None:
    """STIMULUS positions (mm, top-left origin) of the --targets grid, or None."""
    from eyehil.drivers.calibration import grid, screen_to_stimulus
    from eyehil.drivers.setup_file import load_geometry

    if not args.targets:
        return None
    if not args.geometry:
        raise ValueError("--targets needs --geometry (the screen's size)")
    columns, rows = (int(v) for v in args.targets.lower().split("x"))
    screen = load_geometry(args.geometry).geometry.screen
    return screen_to_stimulus(screen, grid(screen, columns, rows, 0.9))
