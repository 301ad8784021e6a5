"""Soak and STIMULUS latency of the native device over pseudo-terminals: `python -m bench soak`.

1. STIMULUS ACK latency while streaming (real clock, 1 kHz, pty): `SOAK_STIMULI` STIMULUS commands at new
   positions, each one's round trip measured on the host (the device must answer without waiting for the
   subject's fixation solve). Target: p99 <= 10 ms.
2. Soak, `SOAK_S` seconds (default 600): device A streams FEATURES at 1 kHz, device B FEATURES + camera
   frames at 100 Hz, each in its own process on its own pty, each read by a host here; a third process sends
   hostile input into A's pty the whole time (random bytes, floods of GET_INFO, STIMULUS with absurd
   positions, CONFIGURE while streaming, oversized frames) at about `SOAK_HOSTILE_BPS` bytes/s. Every 10 s
   the devices' RSS and open descriptors are sampled. Figures: samples received and lost on each pty
   (lost must be 0), RSS and descriptors after the first minute vs the end (flat: within 5 %).
3. The same over ZeroMQ, for `SOAK_S` seconds too: the Pupil facade (`python -m bench.zmq serve`) publishing
   `pupil.0.2d` at 1 kHz and gray 640 x 480 `frame.eye.0` at 100 Hz to a raw pyzmq subscriber here, while a
   hostile process sends Pupil Remote garbage (random bytes, notifications with absurd timestamps and
   positions, oversized msgpack, annotations) to the same facade. The shortfall is exact: every datum carries
   its topic's sequence number (`seq`; an image its `index`, which counts every image offered, rendered or
   not), so received vs (last - first + 1) per topic counts what the
   subscriber missed (ZeroMQ drops at a slow subscriber's high-water mark by design); RSS and descriptors of
   the facade as above.

Environment: SOAK_S, SOAK_STIMULI, SOAK_HOSTILE_BPS.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from eyehil.drivers.client import open_tracker
from eyehil.drivers.errors import TrackerTimeoutError
from eyehil.protocols.enums import StreamSelect

ROOT = Path(__file__).resolve().parent.parent
DEVICE = """
import sys, time
from eyehil.emulator.device.build import DeviceOptions, build_device
from eyehil.emulator.device.links.base import LinkRunner
from eyehil.emulator.device.links.pty import PtyLink
options = DeviceOptions(rate_hz=int(sys.argv[1]), clock="real", solves=sys.argv[2])
with LinkRunner(build_device(options), PtyLink()) as runner:
    print(runner.url, flush=True)
    sys.stdin.read()  # until the parent closes our stdin
"""
HOSTILE = """
import os, random, struct, sys, time
sys.path.insert(0, sys.argv[3])
from eyehil.protocols.messages import Configure, GetInfo, Stimulus
from eyehil.protocols.native import encode
fd = os.open(sys.argv[1], os.O_WRONLY | os.O_NOCTTY)
rate, rng, seq, sent = float(sys.argv[2]), random.Random(1), 1, 0
start = time.monotonic()
while True:
    kind = rng.randrange(5)
    if kind == 0:
        data = rng.randbytes(rng.randrange(1, 200))
    elif kind == 1:
        data = b"".join(encode(GetInfo(), seq + k, 0) for k in range(20))
    elif kind == 2:
        data = encode(Stimulus(1, rng.choice([float("nan"), 3e38, -3e38, 5.0]), 1e9, 1), seq, 2**63)
    elif kind == 3:
        data = encode(Configure(2, 65535, 3, 3, 65535, 65535, 65535, 65535), seq, 0)
    else:
        data = b"\\x01" * 5000 + b"\\x00"
    seq += 21
    try:
        os.write(fd, data)
    except BlockingIOError:
        pass
    sent += len(data)
    ahead = sent / rate - (time.monotonic() - start)
    if ahead > 0:
        time.sleep(ahead)
"""
HOSTILE_ZMQ = """
import random, sys, time
import msgpack, zmq
port, rate = int(sys.argv[1]), float(sys.argv[2])
ctx = zmq.Context()
rng, sent, start = random.Random(2), 0, time.monotonic()
def request():
    kind = rng.randrange(6)
    if kind == 0:
        return [rng.randbytes(rng.randrange(1, 300))]
    if kind == 1:
        note = {"subject": "eyehil.stimulus", "x": rng.choice([float("nan"), 1e308, -3e38, 0.5]),
                "y": 0.5, "timestamp": rng.choice([1e308, -1e308, 9.3e12, float("inf")])}
        return ["notify.eyehil.stimulus", msgpack.packb(note)]
    if kind == 2:
        note = {"subject": "calibration.add_ref_data", "ref_data": [{"norm_pos": [0.5, 0.5],
                "timestamp": rng.choice([1e308, float("nan"), -1.0])}] * rng.randrange(1, 50)}
        return ["notify.calibration.add_ref_data", msgpack.packb(note)]
    if kind == 3:
        return ["notify.x", msgpack.packb([[]] * 200_000)]
    if kind == 4:
        return ["R " + "x" * rng.randrange(0, 500)]
    return [rng.choice(["t", "T nan", "T 1e300", "v", "SUB_PORT", "PUB_PORT", "r"])]
while True:
    req = ctx.socket(zmq.REQ)
    req.setsockopt(zmq.LINGER, 0)
    req.setsockopt(zmq.RCVTIMEO, 2000)
    req.connect(f"tcp://127.0.0.1:{port}")
    parts = [p.encode() if isinstance(p, str) else p for p in request()]
    try:
        req.send_multipart(parts)
        req.recv_multipart()
    except zmq.ZMQError:
        pass
    req.close()
    sent += sum(map(len, parts))
    ahead = sent / rate - (time.monotonic() - start)
    if ahead > 0:
        time.sleep(ahead)
"""


def _device(rate_hz: int, solves: str = "auto") -> tuple[subprocess.Popen, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-c", DEVICE, str(rate_hz), solves], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    return proc, proc.stdout.readline().strip()


def _resources(pid: int) -> tuple[int, int]:
    """RSS (KiB) and open descriptors of process `pid`."""
    rss = next(int(line.split()[1]) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
               if line.startswith("VmRSS:"))
    return rss, len(os.listdir(f"/proc/{pid}/fd"))


def stimulus_latency(count: int, new_positions: bool = True, solves: str = "auto") -> dict:
    """Round trips (ms) of `count` STIMULUS commands while streaming 1 kHz over a pty, each at a new position
    (each starts a fixation solve) or, without `new_positions`, all at one position (no solve: the control);
    `solves`: the device's `DeviceOptions.solves`. A STIMULUS the host gave up on (TrackerTimeoutError after its
    retries) counts as `unanswered`, its round trip as the time the host spent on it."""
    proc, url = _device(1000, solves)
    unanswered = 0
    try:
        with open_tracker(url, timeout=10.0) as tracker:
            tracker.configure(rate_hz=1000)
            tracker.start()
            rng = random.Random(3)
            trips = []
            for i in range(count):
                tracker.drain(max_s=0.05)
                t0 = time.perf_counter()
                if new_positions or i == 0:
                    x, y = rng.uniform(20, 350), rng.uniform(20, 280)
                try:
                    tracker.stimulus(i, x, y)
                except TrackerTimeoutError:
                    unanswered += 1
                trips.append((time.perf_counter() - t0) * 1e3)
                for _ in tracker.samples(count=20):  # keep streaming between stimuli
                    pass
            stats = tracker.stats
            tracker.stop()
    finally:
        proc.stdin.close()
        proc.wait(30)
    trips = np.array(trips)
    return {"stimuli": count, "p50_ms": float(np.percentile(trips, 50)), "p99_ms": float(np.percentile(trips, 99)),
            "max_ms": float(trips.max()), "retries": stats.retries, "unanswered": unanswered}


def soak(seconds: float, hostile_bps: float) -> dict:
    """The soak of the module docstring."""
    (proc_a, url_a), (proc_b, url_b) = _device(1000), _device(100)
    hostile = subprocess.Popen([sys.executable, "-c", HOSTILE, url_a, str(hostile_bps), str(ROOT)])
    samples = {"a": 0, "b": 0}
    series: list[tuple[float, int, int, int, int]] = []
    try:
        a = open_tracker(url_a, timeout=10.0, retries=20)
        b = open_tracker(url_b, timeout=10.0)
        a.configure(rate_hz=1000)
        b.configure(rate_hz=100, stream=StreamSelect.BOTH)
        a.start()
        b.start()
        start = last = time.monotonic()
        while (now := time.monotonic()) - start < seconds:
            samples["a"] += len(a.drain(max_s=0.02))
            samples["b"] += len(b.drain(max_s=0.02))
            b.wire.images.clear()
            if now - last >= 10.0 or not series:
                series.append((now - start, *_resources(proc_a.pid), *_resources(proc_b.pid)))
                last = now
        series.append((time.monotonic() - start, *_resources(proc_a.pid), *_resources(proc_b.pid)))
        result = {"seconds": seconds, "hostile_bps": hostile_bps, "samples_a": samples["a"], "samples_b": samples["b"],
                  "lost_a": a.stats.lost_frames, "lost_b": b.stats.lost_frames,
                  "skipped_a": a.stats.skipped_exposures, "skipped_b": b.stats.skipped_exposures,
                  "images_b": b.stats.images, "stale_a": a.stats.stale_replies, "crc_a": a.stats.crc_errors}
        a.stop()
        b.stop()
        status_a = a.status()
        result.update(device_a_crc=status_a.crc_errors, device_a_framing=status_a.framing_errors,
                      device_a_oversized=status_a.oversized_frames, device_a_refused=status_a.commands_refused,
                      device_a_dropped=status_a.samples_dropped, device_b_dropped=b.status().samples_dropped)
        a.close()
        b.close()
    finally:
        hostile.kill()
        hostile.wait(30)
        for proc in (proc_a, proc_b):
            proc.stdin.close()
            proc.wait(30)
    after_minute = next((row for row in series if row[0] >= 60.0), series[0])
    result.update(series=series, rss_a_kib=(after_minute[1], series[-1][1]), fds_a=(after_minute[2], series[-1][2]),
                  rss_b_kib=(after_minute[3], series[-1][3]), fds_b=(after_minute[4], series[-1][4]))
    return result


def soak_zmq(seconds: float, hostile_bps: float) -> dict:
    """Part 3 of the module docstring: the Pupil facade at 1 kHz datums + 100 Hz images under hostile requests."""
    import msgpack
    import zmq

    from bench.zmq import facade_process

    with facade_process("--rate", "1000", "--frame-rate", "100") as (port, proc):
        hostile = subprocess.Popen([sys.executable, "-c", HOSTILE_ZMQ, str(port), str(hostile_bps)])
        ctx = zmq.Context()
        ctx.linger = 0
        seqs: dict[str, list[int]] = {"pupil": [], "frame": []}
        stamps: list[float] = []  # pupil datums' timestamps (s): the exposures the device made
        series: list[tuple[float, int, int]] = []
        try:
            req = ctx.socket(zmq.REQ)
            req.setsockopt(zmq.RCVTIMEO, 10_000)
            req.connect(f"tcp://127.0.0.1:{port}")
            req.send_string("SUB_PORT")
            sub = ctx.socket(zmq.SUB)
            sub.setsockopt(zmq.RCVTIMEO, 1000)
            sub.connect(f"tcp://127.0.0.1:{req.recv_string()}")
            for prefix in ("pupil.0.2d", "frame.eye.0"):
                sub.setsockopt_string(zmq.SUBSCRIBE, prefix)
            start = last = time.monotonic()
            while (now := time.monotonic()) - start < seconds:
                try:
                    frames = sub.recv_multipart(copy=False)
                except zmq.Again:
                    continue
                name = "frame" if frames[0].bytes.startswith(b"frame.") else "pupil"
                payload = msgpack.unpackb(frames[1].bytes)
                seqs[name].append(int(payload["index"] if name == "frame" else payload["seq"]))
                if name == "pupil":
                    stamps.append(float(payload["timestamp"]))
                if now - last >= 10.0 or not series:
                    series.append((now - start, *_resources(proc.pid)))
                    last = now
            series.append((time.monotonic() - start, *_resources(proc.pid)))
            req.send_string("t")  # the facade still answers after all that
            answered = float(req.recv_string()) > 0
        finally:
            hostile.kill()
            hostile.wait(30)
            ctx.destroy(linger=0)
    exposures = round((max(stamps) - min(stamps)) * 1000) + 1 if stamps else 0  # 1 kHz over the datums' span
    result: dict = {"seconds": seconds, "hostile_bps": hostile_bps, "answered": answered, "exposures": exposures}
    for name, got in seqs.items():
        span = max(got) - min(got) + 1 if got else 0
        result |= {f"{name}_received": len(got), f"{name}_offered": span, f"{name}_missed": span - len(set(got)),
                   f"{name}_duplicates": len(got) - len(set(got))}
    after_minute = next((row for row in series if row[0] >= 60.0), series[0])
    result.update(rss_kib=(after_minute[1], series[-1][1]), fds=(after_minute[2], series[-1][2]))
    return result


def run(repeats: int) -> dict:
    """The three parts (repeats are ignored: one long run)."""
    seconds, bps = float(os.environ.get("SOAK_S", "600")), float(os.environ.get("SOAK_HOSTILE_BPS", "20000"))
    return {"latency": stimulus_latency(int(os.environ.get("SOAK_STIMULI", "200"))),
            "soak": soak(seconds, bps), "zmq": soak_zmq(seconds, bps)}


def report(results: dict) -> str:
    """Three lines: latency, soak on ptys, soak on ZeroMQ."""
    lat, s, z = results["latency"], results["soak"], results["zmq"]
    z_growth = 100.0 * (z["rss_kib"][1] - z["rss_kib"][0]) / z["rss_kib"][0]
    growth = [100.0 * (end - first) / first for first, end in (s["rss_a_kib"], s["rss_b_kib"])]
    return (f"soak stimulus: {lat['stimuli']} STIMULUS while streaming 1 kHz on a pty: ACK p50 {lat['p50_ms']:.2f} ms, "
            f"p99 {lat['p99_ms']:.2f} ms, max {lat['max_ms']:.2f} ms, {lat['retries']} retries, "
            f"{lat['unanswered']} unanswered\n"
            f"soak {s['seconds']:.0f} s: pty A 1 kHz features + hostile input ({s['hostile_bps']:.0f} B/s): "
            f"{s['samples_a']:,} samples, {s['lost_a']} lost, {s['skipped_a']} skipped; pty B 100 Hz features+frames: "
            f"{s['samples_b']:,} samples, {s['images_b']:,} images, {s['lost_b']} lost, {s['skipped_b']} skipped; "
            f"RSS A {s['rss_a_kib'][0] / 1024:.1f} -> {s['rss_a_kib'][1] / 1024:.1f} MiB ({growth[0]:+.1f} %), "
            f"fds A {s['fds_a'][0]} -> {s['fds_a'][1]}; RSS B {s['rss_b_kib'][0] / 1024:.1f} -> "
            f"{s['rss_b_kib'][1] / 1024:.1f} MiB ({growth[1]:+.1f} %), fds B {s['fds_b'][0]} -> {s['fds_b'][1]}; "
            f"device A refused {s['device_a_refused']}, CRC {s['device_a_crc']}, framing {s['device_a_framing']}, "
            f"oversized {s['device_a_oversized']}\n"
            f"soak {z['seconds']:.0f} s ZeroMQ: pupil.0.2d 1 kHz + frame.eye.0 100 Hz + hostile requests "
            f"({z['hostile_bps']:.0f} B/s): {z['exposures']:,} exposures at 1 kHz, datums published "
            f"{z['pupil_offered']:,}, received {z['pupil_received']:,} "
            f"(missed {z['pupil_missed']:,}, duplicated {z['pupil_duplicates']}), images {z['frame_received']:,} of "
            f"{z['frame_offered']:,} (missed {z['frame_missed']:,}); RSS {z['rss_kib'][0] / 1024:.1f} -> "
            f"{z['rss_kib'][1] / 1024:.1f} MiB ({z_growth:+.1f} %), "
            f"fds {z['fds'][0]} -> {z['fds'][1]}; Remote still answers: {z['answered']}")
