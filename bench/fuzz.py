"""Mutation fuzzing of every parser a peer or a file can reach: `python -m bench fuzz`.

Each parser (`PARSERS`) has valid seed inputs; a run applies random byte-level mutations (flip, insert,
delete, duplicate a slice, splice another seed, overwrite with an interesting number, truncate) to
`FUZZ_INPUTS` inputs per parser (default 1,000,000) and feeds them to the parser. The parser may accept an
input or raise its package's documented error; anything else (another exception), a hang (an input
taking more than `HANG_S` of CPU time: wall time on a shared machine measures the scheduler) or growing
memory (peak RSS) is a finding. Inputs that found a bug are written
to tests/corpus/<parser>/ (replayed by tests/test_reliability_parsers.py).

Parsers and their documented errors:

- native: `eyehil.protocols.stream.NativeReceiver.feed` (never raises) on a byte stream, decoding every frame
- iscan: `eyehil.protocols.iscan.IscanParser.feed` (never raises) with 1..4 outputs, plain and confirmed
- pupil: `eyehil.protocols.pupil.unpack`, `parse_request`, `parse_ref_data` -> `PupilMessageError`
- usbip: op header, devlist reply, import busid, URB header -> `UsbipError`
- recording: `eyehil.drivers.recording.parse_recording_bytes` -> `RecordingError`
- scene: `eyehil.emulator.scene.loader.scene_from_toml_bytes` -> `SceneError`

Environment: FUZZ_INPUTS (per parser), FUZZ_PARSERS (comma list), FUZZ_SEED.
"""

from __future__ import annotations

import json
import os
import random
import resource
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import msgpack

from eyehil.drivers.errors import RecordingError
from eyehil.drivers.recording import parse_recording_bytes
from eyehil.emulator.scene import SceneError
from eyehil.emulator.scene.loader import scene_from_toml_bytes
from eyehil.protocols.enums import Eye, PupilFlags
from eyehil.protocols.iscan import IscanParser, encode_sample
from eyehil.protocols.messages import Configure, GetInfo, Ping, Stimulus
from eyehil.protocols.native import encode
from eyehil.protocols.pupil import PupilMessageError, parse_ref_data, parse_request, unpack
from eyehil.protocols.replies import Ack, ErrorReply
from eyehil.protocols.samples import EyeFeatures, Features, FrameChunk, Glint
from eyehil.protocols.stream import NativeReceiver
from eyehil.protocols.usbip.messages import (
    OP_HEADER,
    OpHeader,
    UsbipError,
    cdc_acm_device,
    decode_busid,
    decode_devlist_reply,
    encode_devlist_reply,
    encode_import_request,
)
from eyehil.protocols.usbip.urb import URB_HEADER_SIZE, CmdSubmit, decode_urb_header

CORPUS = Path(__file__).resolve().parent.parent / "tests" / "corpus"
HANG_S = 1.0
INTERESTING = [0, 1, 0x7F, 0x80, 0xFF, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF, -1, 1 << 31, 1 << 63]


class FindingError(AssertionError):
    """A parser let an undocumented exception escape."""


@dataclass(frozen=True)
class Parser:
    """A parser under test: `call(raw)` and the exception types it may raise."""

    name: str
    call: Callable[[bytes], object]
    documented: tuple[type[BaseException], ...]
    seed_inputs: Callable[[], list[bytes]]

    def run(self, raw: bytes) -> None:
        """Feed `raw`; raise `FindingError` if anything but the documented errors escapes."""
        try:
            self.call(raw)
        except self.documented:
            pass
        except Exception as exc:
            raise FindingError(f"{self.name}: {type(exc).__name__}: {exc}") from exc


# --- parsers -------------------------------------------------------------------------------------------------------
def _native(raw: bytes) -> None:
    NativeReceiver().feed(raw)


def _native_seeds() -> list[bytes]:
    eye = EyeFeatures(Eye.RIGHT, PupilFlags.DETECTED, 310.5, 240.25, 30.0, 28.0, 12.0, 0.9,
                      (Glint(0, 300.0, 250.0), Glint(1, 320.0, 250.0)))
    chunk = FrameChunk(7, Eye.RIGHT, 1, 16, 8, 0, 0, 0, 1, 0, bytes(range(128)))
    messages = [Ping(5), GetInfo(), Configure(2, 500), Stimulus(1, 10.0, 20.0), Features(3, (eye,)), chunk,
                Ack(4, 3), ErrorReply(5, 6, 3, "no")]
    return [b"".join(encode(m, i, 1000 * i) for i, m in enumerate(messages))] + [encode(m, 9, 9) for m in messages]


def _iscan(raw: bytes) -> None:
    n = 1 + (raw[0] % 4 if raw else 0)
    parser = IscanParser(n, confirm=bool(raw and raw[0] & 0x10))
    parser.feed(raw[:1])
    parser.feed(raw[1:])


def _iscan_seeds() -> list[bytes]:
    return [bytes([k]) + b"".join(encode_sample([100.0 + i, 80.0, 90.0, 85.0][: k + 1]) for i in range(6))
            for k in range(4)]


def _pupil(raw: bytes) -> None:
    cut = raw[0] % max(len(raw), 1) if raw else 0
    topic, payload = unpack([raw[1:cut], raw[cut:]])
    parse_ref_data(payload)
    parse_request([raw])
    parse_request([raw[:cut], raw[cut:]])
    _ = topic


def _pupil_seeds() -> list[bytes]:
    note = {"topic": "notify.calibration.add_ref_data", "subject": "calibration.add_ref_data",
            "ref_data": [{"norm_pos": [0.5, 0.5], "timestamp": 12.5}, {"norm_pos": [0.1, 0.9], "timestamp": 13.0}]}
    stim = {"topic": "notify.eyehil.stimulus", "norm_pos": [0.2, 0.3], "timestamp": 1.0}
    out = []
    for payload in (note, stim):
        topic = payload["topic"].encode()
        packed = msgpack.packb(payload, use_bin_type=True)
        out.append(bytes([len(topic) + 1]) + topic + packed)
    return [*out, b"T 1234.5", b"R session", b"SUB_PORT"]


def _usbip(raw: bytes) -> None:
    kind = raw[0] % 4 if raw else 0
    body = raw[1:]
    if kind == 0:
        OpHeader.decode(body[: OP_HEADER.size]) if len(body) >= OP_HEADER.size else OpHeader.decode(body)
    elif kind == 1:
        decode_devlist_reply(body)
    elif kind == 2:
        decode_busid(body)
    else:
        decode_urb_header(body[:URB_HEADER_SIZE])


def _usbip_seeds() -> list[bytes]:
    urb = CmdSubmit(seqnum=1, devid=0x10002, direction=0, ep=2, transfer_buffer_length=4, data=b"abcd")
    return [b"\x00" + OpHeader(0x8005).encode(), b"\x01" + encode_devlist_reply([cdc_acm_device()]),
            b"\x02" + encode_import_request("1-1")[OP_HEADER.size:], b"\x03" + urb.encode()]


def _recording_seeds() -> list[bytes]:
    header = {"format": "eyehil-recording", "version": 1, "device": {}, "configuration": None}
    eye = {"eye": 0, "flags": 1, "centre": [300.5, 240.0], "axes": [30.0, 28.0], "angle_deg": 10.0, "confidence": 0.9,
           "glints": [{"led": 0, "flags": 1, "x": 290.0, "y": 250.0}]}
    sample = {"type": "sample", "seq": 5, "frame_id": 9, "device_us": 1000, "host_us": 2000, "lost_before": 0,
              "skipped_before": 1, "target_id": 1, "eyes": [eye]}
    target = {"type": "target", "host_us": 1, "device_us": 2, "target_id": 1, "x_mm": 1.0, "y_mm": 2.0,
              "visible": True, "label": ""}
    lines = [header, target, sample, dict(sample, seq=6, frame_id=10), {"type": "end", "stats": {}}]
    return ["\n".join(json.dumps(x) for x in lines).encode() + b"\n"]


def _scene_seeds() -> list[bytes]:
    preset = Path(__file__).resolve().parent.parent / "emulator" / "scene" / "presets"
    return [p.read_bytes() for p in sorted(preset.glob("*.toml"))[:3]]


PARSERS: dict[str, Parser] = {p.name: p for p in (
    Parser("native", _native, (), _native_seeds),
    Parser("iscan", _iscan, (), _iscan_seeds),
    Parser("pupil", _pupil, (PupilMessageError,), _pupil_seeds),
    Parser("usbip", _usbip, (UsbipError,), _usbip_seeds),
    Parser("recording", lambda raw: parse_recording_bytes(raw, "fuzz"), (RecordingError,), _recording_seeds),
    Parser("scene", scene_from_toml_bytes, (SceneError,), _scene_seeds),
)}
_SEEDS: dict[str, list[bytes]] = {}


def seeds(name: str) -> list[bytes]:
    """The seed inputs of parser `name` (built once)."""
    if name not in _SEEDS:
        _SEEDS[name] = PARSERS[name].seed_inputs()
    return _SEEDS[name]


# --- mutations -----------------------------------------------------------------------------------------------------
def mutate(data: bytes, mutations: list[tuple[int, int, bytes]], other: bytes = b"") -> bytes:
    """Apply (kind, position, bytes) mutations to `data`; deterministic (hypothesis draws them in the tests)."""
    buf = bytearray(data)
    for kind, pos, extra in mutations:
        at = pos % (len(buf) + 1)
        if kind == 0 and buf:  # flip bits
            buf[at % len(buf)] ^= (extra[0] if extra else 1) or 1
        elif kind == 1:  # insert bytes
            buf[at:at] = extra
        elif kind == 2:  # delete a slice
            del buf[at:at + 1 + (extra[0] if extra else 0) % 16]
        elif kind == 3 and buf:  # duplicate a slice
            end = min(len(buf), at + 1 + (extra[0] if extra else 0) % 64)
            buf[at:at] = buf[at:end]
        elif kind == 4:  # overwrite with an interesting number
            value = INTERESTING[(extra[0] if extra else 0) % len(INTERESTING)]
            packed = struct.pack("<q" if value < 0 else "<Q", value)[: 1 + (pos % 8)]
            buf[at:at + len(packed)] = packed
        elif kind == 5:  # splice another input
            src = other or data
            buf[at:] = src[pos % (len(src) + 1):]
        elif kind == 6:  # truncate
            del buf[at:]
    return bytes(buf)


def random_mutations(rng: random.Random, length: int) -> list[tuple[int, int, bytes]]:
    """1..8 random mutations for an input of `length` bytes."""
    return [(rng.randrange(7), rng.randrange(length + 8), rng.randbytes(rng.randrange(1, 9)))
            for _ in range(rng.randrange(1, 9))]


def _rss_kib() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)


def fuzz(name: str, count: int, seed: int = 0) -> dict:
    """Run `count` mutated inputs through parser `name`; return the figures (and save findings to the corpus)."""
    parser, base = PARSERS[name], seeds(name)
    rng = random.Random(seed)
    findings, slowest, accepted = 0, 0.0, 0
    rss = []
    start = time.perf_counter()
    for i in range(count):
        data = base[rng.randrange(len(base))]
        raw = mutate(data, random_mutations(rng, len(data)), base[rng.randrange(len(base))])
        t0 = time.process_time()
        try:
            parser.call(raw)
            accepted += 1
        except parser.documented:
            pass
        except Exception as exc:  # a finding: keep the input
            findings += 1
            if findings <= 20:
                folder = CORPUS / name
                folder.mkdir(parents=True, exist_ok=True)
                (folder / f"{type(exc).__name__}-{seed}-{i}.bin").write_bytes(raw)
        slowest = max(slowest, time.process_time() - t0)
        if i % max(count // 10, 1) == 0:
            rss.append(_rss_kib())
    rss.append(_rss_kib())
    return {"parser": name, "inputs": count, "accepted": accepted, "findings": findings,
            "hangs": int(slowest > HANG_S), "slowest_ms": slowest * 1e3, "seconds": time.perf_counter() - start,
            "rss_first_kib": rss[min(1, len(rss) - 1)], "rss_last_kib": rss[-1],
            "peak_rss_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}


def run(repeats: int) -> list[dict]:
    """`python -m bench fuzz`: every parser (FUZZ_PARSERS), FUZZ_INPUTS inputs each (repeats are ignored)."""
    count = int(os.environ.get("FUZZ_INPUTS", "1000000"))
    names = [n for n in os.environ.get("FUZZ_PARSERS", ",".join(PARSERS)).split(",") if n]
    seed = int(os.environ.get("FUZZ_SEED", "0"))
    return [fuzz(name, count, seed) for name in names]


def report(results: list[dict]) -> str:
    """One line per parser."""
    return "\n".join(
        f"fuzz {r['parser']:<9} {r['inputs']:>9,} inputs in {r['seconds']:7.1f} s: {r['findings']} undocumented "
        f"exceptions, {r['hangs']} hangs (slowest {r['slowest_ms']:.1f} ms CPU), {r['accepted']:,} accepted; RSS "
        f"{r['rss_first_kib'] / 1024:.1f} -> {r['rss_last_kib'] / 1024:.1f} MiB" for r in results)
