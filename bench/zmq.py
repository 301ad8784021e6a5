"""Benchmark: the ZeroMQ facade (Pupil Core Network API) streaming pupil datums and eye images to a subscriber.

The facade runs in its own process (`python -m bench.zmq serve`: scene guestrin2006, the demo script with its
saccades, pursuit and blinks, real clock, `pupil.0.2d` and `glint.0` at RATE_HZ, gray full-sensor 640 x 480
`frame.eye.0` at FRAME_HZ), with a GIL switch interval of SWITCH_INTERVAL_S (Python's default, 5 ms, lets
the rendering thread hold the datums up for that long). This process subscribes with raw pyzmq, as
pupil-helpers' filter_messages.py does, to ``pupil.`` and ``frame.eye.`` for SECONDS after a warm-up, having
estimated the clock offset from ten ``t`` requests as the real client does. Per stream: delivered, dropped
(pupil datums: gaps in the timestamp sequence, whose spacing is exactly 1 / RATE_HZ; images: gaps in
`index`, which counts every image the facade offered, rendered or not) and latency = arrival - (timestamp -
offset), p50 / p99 / max. Images are stamped at mid-exposure and rendered afterwards, so their latency
includes the rendering. Where the images are rendered (`render_pool`): in two worker processes (the case
reported first: one per core of the benchmark machine), in one, on the facade's frame thread (sharing the
interpreter lock with the datums, as before issue 16), and in a pool of two threads; the variants alternate
within each repeat, so they meet the same load. Each run streams for SECONDS = 30 s, as issue 16 asks.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager

import msgpack
import numpy as np
import zmq

RATE_HZ = 1000
FRAME_HZ = 200
SECONDS = 30.0
WARMUP_S = 1.0
#: The facade process's GIL switch interval: the device thread waits at most this long for the frame thread.
SWITCH_INTERVAL_S = 0.0005
#: Images rendered in this many processes (`ServerOptions.render_workers`); `VARIANTS` are measured in the same run.
RENDER_WORKERS = 2
VARIANTS = {"processes x2": ("--render-workers", "2"), "process x1": ("--render-workers", "1"),
            "frame thread": ("--render-workers", "0"),
            "thread pool x2": ("--render-workers", "2", "--render-kind", "thread")}


def serve(argv: list[str]) -> None:
    """The facade process: prints ``port: N`` and serves until SIGTERM."""
    from eyehil.emulator.device.build import DeviceOptions, build_subject
    from eyehil.emulator.device.pupil.server import PupilServer, ServerOptions
    from eyehil.stopping import wait_for_stop

    p = argparse.ArgumentParser(prog="python -m bench.zmq serve")
    p.add_argument("--rate", type=int, default=RATE_HZ)
    p.add_argument("--frame-rate", type=float, default=FRAME_HZ)
    p.add_argument("--world-rate", type=float, default=0.0, help="frame.world per second (0: none, as measured)")
    p.add_argument("--switch", type=float, default=SWITCH_INTERVAL_S, help="sys.setswitchinterval (s)")
    p.add_argument("--render-workers", type=int, default=RENDER_WORKERS, help="0: render on the frame thread")
    p.add_argument("--render-kind", choices=["process", "thread"], default="process")
    args = p.parse_args(argv)
    sys.setswitchinterval(args.switch)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    subject = build_subject(DeviceOptions(scene="guestrin2006", script="demo"))
    options = ServerOptions(port=0, rate_hz=args.rate, frame_rate_hz=args.frame_rate, frame_size=None,
                            world_rate_hz=args.world_rate, render_workers=args.render_workers,
                            render_kind=args.render_kind)
    with PupilServer(subject, options=options) as server:
        print(f"port: {server.port}", flush=True)
        wait_for_stop(stop)  # in slices: SIGTERM may land on a worker thread (eyehil.stopping)


@contextmanager
def facade_process(*extra: str):
    """Start the facade process; yield its Pupil Remote port and the process."""
    proc = subprocess.Popen([sys.executable, "-m", "bench.zmq", "serve", *extra], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        if not line.startswith("port:"):
            raise RuntimeError("the facade did not start")
        yield int(line.split()[1]), proc
    finally:
        proc.terminate()
        proc.wait(timeout=20)


@contextmanager
def facade(*extra: str):
    """Start the facade process; yield its Pupil Remote port."""
    with facade_process(*extra) as (port, _):
        yield port


def clock_offset(req: zmq.Socket, n: int = 10) -> float:
    """Mean (Pupil time - local monotonic time) over `n` ``t`` requests (s)."""
    offsets = []
    for _ in range(n):
        before = time.monotonic()
        req.send_string("t")
        remote = float(req.recv_string())
        offsets.append(remote - (before + time.monotonic()) / 2)
    return float(np.mean(offsets))


def collect(port: int, seconds: float) -> dict[str, list]:
    """Arrival time and payload fields of every pupil datum and image received in `seconds` after the warm-up."""
    ctx = zmq.Context()
    ctx.rcvtimeo, ctx.linger = 10_000, 0
    try:
        req = ctx.socket(zmq.REQ)
        req.connect(f"tcp://127.0.0.1:{port}")
        req.send_string("SUB_PORT")
        sub = ctx.socket(zmq.SUB)
        sub.connect(f"tcp://127.0.0.1:{req.recv_string()}")
        for prefix in ("pupil.", "frame.eye."):
            sub.setsockopt_string(zmq.SUBSCRIBE, prefix)
        offset = clock_offset(req)
        rows: dict[str, list] = {"pupil": [], "frame": [], "offset": [offset], "bad_frames": [0]}
        start = time.monotonic()
        while (now := time.monotonic()) < start + WARMUP_S + seconds:
            frames = sub.recv_multipart(copy=False)
            arrival = time.monotonic()
            if now < start + WARMUP_S:
                continue
            payload = msgpack.unpackb(frames[1].bytes)
            if frames[0].bytes.startswith(b"frame."):
                rows["bad_frames"][0] += len(frames[2]) != payload["width"] * payload["height"]
                rows["frame"].append((arrival, payload["timestamp"], payload["index"]))
            else:
                rows["pupil"].append((arrival, payload["timestamp"]))
        return rows
    finally:
        ctx.destroy(linger=0)


def summarise(rows: dict[str, list]) -> dict[str, float]:
    """Delivered, dropped and latency percentiles (ms) of both streams."""
    offset = rows["offset"][0]
    out: dict[str, float] = {"bad_frames": rows["bad_frames"][0]}
    for name in ("pupil", "frame"):
        data = np.array(rows[name], float).reshape(-1, 3 if name == "frame" else 2)
        latency = (data[:, 0] - (data[:, 1] - offset)) * 1e3
        if not len(data):
            latency = np.full(1, np.nan)
        if name == "pupil":
            ts = np.unique(np.round((data[:, 1] - data[:, 1].min()) * RATE_HZ))
            expected = int(ts[-1]) + 1 if len(ts) else 0
        else:
            idx = np.unique(data[:, 2])
            expected = int(idx[-1] - idx[0]) + 1 if len(idx) else 0
        out |= {f"{name}_delivered": len(data), f"{name}_dropped": expected - len(np.unique(data[:, -1])),
                f"{name}_p50_ms": float(np.percentile(latency, 50)), f"{name}_max_ms": float(latency.max()),
                f"{name}_p99_ms": float(np.percentile(latency, 99)), f"{name}_rate_hz": len(data) / SECONDS}
    return out


def run_variant(repeats: int, *extra: str) -> dict[str, float]:
    """The best (lowest pupil p99) of `repeats` runs, each against a fresh facade process started with `extra`."""
    best: dict[str, float] | None = None
    for _ in range(repeats):
        with facade(*extra) as port:
            result = summarise(collect(port, SECONDS))
        if best is None or result["pupil_p99_ms"] < best["pupil_p99_ms"]:
            best = result
    return best


def run(repeats: int = 3) -> dict:
    """Each of `VARIANTS` (where images are rendered), interleaved run by run so they share the machine's load."""
    results: dict[str, dict[str, float]] = {}
    dropped: dict[str, list[float]] = {name: [] for name in VARIANTS}
    for _ in range(repeats):
        for name, extra in VARIANTS.items():
            r = run_variant(1, *extra)
            dropped[name].append(r["frame_dropped"])
            if name not in results or r["pupil_p99_ms"] < results[name]["pupil_p99_ms"]:
                results[name] = r
    for name, r in results.items():
        r["frame_dropped_runs"] = dropped[name]  # every run's, not only the best one's
    return {"variants": results, "repeats": repeats, "best": results[next(iter(VARIANTS))]}


def report(results: dict) -> str:
    """One paragraph: both streams' delivery and latency."""
    b = results["best"]
    lines = [f"ZeroMQ facade, {SECONDS:.0f} s to one raw pyzmq subscriber (guestrin2006, demo script, GIL switch "
             f"interval {SWITCH_INTERVAL_S * 1e3:g} ms):"]
    streams = (("pupil", f"pupil.0.2d at {RATE_HZ} Hz"), ("frame", f"gray 640x480 frame.eye.0 at {FRAME_HZ} Hz"))
    for name, what in streams:
        lines.append(f"  {what}: delivered {b[f'{name}_delivered']:.0f} ({b[f'{name}_rate_hz']:.1f}/s), dropped "
                     f"{b[f'{name}_dropped']:.0f}; latency p50 {b[f'{name}_p50_ms']:.2f} ms, p99 "
                     f"{b[f'{name}_p99_ms']:.2f} ms, max {b[f'{name}_max_ms']:.1f} ms")
    runs = b.get("frame_dropped_runs", [b["frame_dropped"]])
    verdict = "PASS" if max(runs) == 0 else "FAIL"
    lines.append(f"  frames dropped in each of the {len(runs)} runs: {', '.join(f'{d:.0f}' for d in runs)} "
                 f"(target 0, issue 16: {verdict})")
    lines.append(f"  frames whose buffer was not width x height bytes: {b['bad_frames']:.0f}")
    lines[0] = lines[0].replace("):", f"; images rendered by {next(iter(VARIANTS))}):")
    for name, r in list(results.get("variants", {}).items())[1:]:
        runs = r.get("frame_dropped_runs", [r["frame_dropped"]])
        lines.append(f"  images rendered by {name}: frames delivered {r['frame_delivered']:.0f}, dropped "
                     f"{', '.join(f'{d:.0f}' for d in runs)}; pupil dropped {r['pupil_dropped']:.0f}, p99 "
                     f"{r['pupil_p99_ms']:.2f} ms")
    return "\n".join(lines)


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        serve(sys.argv[2:])
    else:
        print(report(run(1)))
