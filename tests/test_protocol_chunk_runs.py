"""FRAME_CHUNKs in runs (`ChunkRun`): the host's receiver and image reassembly give what the per-chunk path gives.

A run stands for the `Received` events of its chunks (`ChunkRun.received`), so a receiver with `chunk_runs` must
report, once its runs are expanded, exactly the events, counters and framer state of the per-frame path (the
compiled kernels switched off); and a `Wire` (which asks for runs) must deliver the same images, with the same
device times and sequence numbers, and the same counters. The streams are hostile: chunks lost, duplicated,
swapped, from a restarted sender, with another timestamp, protocol version, frame id, eye, geometry or chunk count
than the chunks before them, an index or offset outside the image, a flipped byte, a short payload, other messages
between them, all cut at random places.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict

import numpy as np
import pytest

from eyehil.drivers import wire as wire_module
from eyehil.drivers.wire import Wire
from eyehil.protocols import DEVICE_TYPES, ChunkRun, Features, FrameChunk, NativeReceiver, Received, kernels
from eyehil.protocols.enums import Eye
from eyehil.protocols.framing import encode_frame
from eyehil.protocols.header import MessageType, pack_frame
from eyehil.protocols.native import encode
from eyehil.protocols.replies import Pong

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason=f"compiled kernels unavailable: {kernels.REASON}")

MUTATIONS = ("lose", "duplicate", "swap", "restart", "timestamp", "version", "frame_id", "eye", "width", "count",
             "index", "offset", "flip", "short", "features", "pong")


def _chunk_frame(seq: int, timestamp: int, head: list[int], data: bytes, version: int = 1) -> bytes:
    """The wire bytes of a FRAME_CHUNK built field by field (so that fields a `FrameChunk` refuses can be sent)."""
    payload = FrameChunk.STRUCT.pack(*head) + data
    return encode_frame(pack_frame(MessageType.FRAME_CHUNK, seq % 2**32, timestamp, payload, version=version))


def _chunk_stream(rng: np.random.Generator) -> tuple[bytes, set[str]]:
    """Images' chunks as a device sends them, one in seven mutated (`MUTATIONS`); and the mutations made."""
    frames: list[bytes] = []
    made: set[str] = set()
    seq = int(rng.integers(0, 2**32))
    for frame_id in range(int(rng.integers(2, 7))):
        eye = int(rng.choice([Eye.LEFT, Eye.RIGHT]))
        fmt, bpp = (2, 2) if rng.random() < 0.3 else (1, 1)  # MONO16, MONO8
        width, height = int(rng.integers(4, 40)), int(rng.integers(2, 30))
        size = width * height * bpp
        step = int(rng.integers(1, max(2, size // 3)))
        count = -(-size // step)
        pixels = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        timestamp = int(rng.integers(0, 2**40))
        for index in range(count):
            head = [frame_id, eye, fmt, width, height, 3, 5, index, count, index * step]
            data = pixels[index * step : (index + 1) * step]
            kind = str(rng.choice(MUTATIONS)) if rng.random() < 1 / 7 else ""
            made.add(kind)
            stamp = timestamp + 1 if kind == "timestamp" else timestamp
            if kind in ("frame_id", "eye", "width", "count", "index", "offset"):
                field = {"frame_id": 0, "eye": 1, "width": 3, "count": 8, "index": 7, "offset": 9}[kind]
                head[field] = {"eye": 1 - eye, "count": count + 1, "index": count, "offset": size}.get(kind,
                                                                                                    head[field] + 1)
            frame = _chunk_frame(seq, stamp, head, data, 2 if kind == "version" else 1)
            if kind == "short":
                frame = encode_frame(pack_frame(MessageType.FRAME_CHUNK, seq % 2**32, stamp, b"\x01" * 9))
            elif kind == "flip":
                at = int(rng.integers(1, len(frame) - 1))
                frame = frame[:at] + bytes([frame[at] ^ 0x21 or 1]) + frame[at + 1 :]
            elif kind == "restart":
                seq += 2**31
                frame = _chunk_frame(seq, stamp, head, data)
            elif kind == "features":
                frames.append(encode(Features(frame_id, ()), seq, stamp))
                seq += 1
                frame = _chunk_frame(seq, stamp, head, data)
            elif kind == "pong":
                frames.append(encode(Pong(1, 2, 3), seq, stamp))
                seq += 1
                frame = _chunk_frame(seq, stamp, head, data)
            if kind == "lose":
                seq += 1
                continue
            frames.append(frame)
            if kind == "duplicate":
                frames.append(frame)
            elif kind == "swap" and len(frames) > 1:
                frames[-1], frames[-2] = frames[-2], frames[-1]
            seq += 1
    return b"".join(frames), made - {""}


def _pieces(rng: np.random.Generator, stream: bytes) -> list[bytes]:
    cuts = np.sort(rng.choice(np.arange(1, len(stream)), size=min(len(stream) - 1, int(rng.integers(0, 12))),
                              replace=False))
    return [stream[a:b] for a, b in itertools.pairwise([0, *cuts.tolist(), len(stream)])]


def _receiver_report(receiver: NativeReceiver, pieces: list[bytes]) -> tuple[list, dict, tuple, int]:
    """Events (runs expanded into their chunks), counters, the framer's state, and the chunks that came in runs
    after a run's first."""
    out, in_runs = [], 0
    for piece in pieces:
        for event in receiver.feed(piece):
            if isinstance(event, ChunkRun):
                in_runs += len(event.rest)
                expanded = event.received()
            else:
                expanded = [event]
            for e in expanded:
                out.append(("received", e.header, e.message, e.lost_before, e.out_of_order) if isinstance(e, Received)
                           else ("rejected", type(e.error).__name__, str(e.error), e.reply))
    f = receiver.framer
    return out, asdict(receiver.counters), (f.frames, f.cobs_errors, f.oversized, f.bytes_discarded, f.pending), in_runs


@pytest.mark.parametrize("seed", range(60))
def test_runs_stand_for_the_events_of_their_chunks(seed: int, monkeypatch) -> None:
    rng = np.random.default_rng(seed)
    stream, _ = _chunk_stream(rng)
    pieces = _pieces(rng, stream)
    for accept, versions in ((None, frozenset({1})), (DEVICE_TYPES, frozenset({1})), (None, frozenset({1, 2}))):
        *runs, _ = _receiver_report(NativeReceiver(accept, versions, chunk_runs=True), pieces)
        *plain, none = _receiver_report(NativeReceiver(accept, versions), pieces)
        with monkeypatch.context() as patch:
            patch.setattr(kernels, "AVAILABLE", False)
            *slow, _ = _receiver_report(NativeReceiver(accept, versions, chunk_runs=True), pieces)
        assert runs == plain == slow
        assert none == 0  # runs only where asked for


class _Pieces:
    """A link that gives one piece a read."""

    timeout = 0.0

    def __init__(self, pieces: list[bytes]) -> None:
        self.pieces = list(pieces)

    def read(self, size: int) -> bytes:
        assert not self.pieces or len(self.pieces[0]) <= size
        return self.pieces.pop(0) if self.pieces else b""

    def write(self, data: bytes) -> int:
        return len(data)


def _wire_report(pieces: list[bytes]) -> tuple[list, dict]:
    wire = Wire(_Pieces(pieces))
    while wire.link.pieces:
        wire.pump(0)
    images = [(g.image.frame_id, g.image.eye, g.image.roi_x, g.image.roi_y, g.image.pixels.dtype.str,
               g.image.pixels.tobytes(), g.device_us, g.host_us, g.seq) for g in wire.images]
    return images, wire.stats.as_dict()


@pytest.mark.parametrize("seed", range(60))
def test_the_host_reassembles_runs_as_it_does_single_chunks(seed: int, monkeypatch) -> None:
    rng = np.random.default_rng(1000 + seed)
    stream, _ = _chunk_stream(rng)
    pieces = _pieces(rng, stream)
    clock = itertools.count()
    monkeypatch.setattr(wire_module, "host_now_us", lambda: next(clock))
    fast = _wire_report(pieces)
    clock = itertools.count()
    with monkeypatch.context() as patch:
        patch.setattr(kernels, "AVAILABLE", False)
        slow = _wire_report(pieces)
    assert fast == slow


def test_the_streams_hold_every_mutation_whole_images_and_runs() -> None:
    """The generator is not idle: over the seeds the tests use, every mutation occurs, images are delivered, and most
    streams have chunks that came in runs."""
    made, images, with_runs = set(), 0, 0
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        stream, kinds = _chunk_stream(rng)
        made |= kinds
        images += len(_wire_report(_pieces(rng, stream))[0])
        rng = np.random.default_rng(seed)
        stream, _ = _chunk_stream(rng)
        with_runs += _receiver_report(NativeReceiver(chunk_runs=True), _pieces(rng, stream))[-1] > 0
    assert made == set(MUTATIONS) and images > 60 and with_runs > 50
