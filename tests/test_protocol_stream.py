"""NativeReceiver under abuse (the device's and host's receive path), and the CONFIGURE rules."""

from __future__ import annotations

import itertools
from dataclasses import asdict

import numpy as np
import pytest

from eyehil.protocols import (
    HOST_TYPES,
    Capability,
    Configure,
    CrcError,
    DeviceInfo,
    ErrorCode,
    EyeSelect,
    FramingFault,
    GetInfo,
    NativeReceiver,
    Ping,
    Received,
    Rejected,
    Start,
    StreamSelect,
    UnknownMessageTypeError,
    UnsupportedVersionError,
    check_configure,
    default_configure,
    encode,
    encode_frame,
    kernels,
)
from eyehil.protocols.header import MessageType, pack_frame

COMMANDS = [Ping(7), GetInfo(), Configure(1, 120), Start()]


def _stream(seq0: int = 0, count: int = 40) -> tuple[bytes, list]:
    """Wire bytes of `count` commands with consecutive sequence numbers, and the commands."""
    messages = [COMMANDS[i % len(COMMANDS)] for i in range(count)]
    return b"".join(encode(m, seq0 + i, 1000 * i) for i, m in enumerate(messages)), messages


def _feed_randomly(receiver: NativeReceiver, data: bytes, rng: np.random.Generator) -> list:
    cuts = sorted(rng.integers(0, len(data) + 1, len(data) // 5 + 1).tolist())
    events = []
    for a, b in itertools.pairwise([0, *cuts, len(data)]):
        events += receiver.feed(data[a:b])
    return events


def test_clean_stream_at_random_boundaries() -> None:
    data, messages = _stream(seq0=2**32 - 20)  # crosses the sequence wrap
    receiver = NativeReceiver(accept=HOST_TYPES)
    events = _feed_randomly(receiver, data, np.random.default_rng(6))
    assert [e.message for e in events] == messages
    assert all(isinstance(e, Received) and e.lost_before == 0 for e in events)
    assert receiver.counters.rx_frames == 40 and receiver.counters.lost_frames == 0


def test_lost_frames_are_counted_from_sequence_gaps() -> None:
    frames = [encode(Ping(i), i, 0) for i in range(10)]
    receiver = NativeReceiver()
    events = receiver.feed(b"".join(frames[:3] + frames[6:]))
    assert [e.lost_before for e in events] == [0, 0, 0, 3, 0, 0, 0]
    assert receiver.counters.lost_frames == 3
    receiver.feed(frames[4])  # old frame: out of order, not lost
    assert receiver.counters.out_of_order == 1


def test_every_kind_of_bad_frame_is_reported_and_the_stream_continues() -> None:
    good = encode(Ping(1), 0, 0)
    bad_crc = bytearray(pack_frame(MessageType.PING, 1, 0, b"\x01\x00\x00\x00"))
    bad_crc[-3] ^= 0xFF
    abuse = [
        encode_frame(bytes(bad_crc)),
        encode_frame(pack_frame(0x3E, 2, 0, b"")),  # unknown type
        encode_frame(pack_frame(MessageType.GET_INFO, 3, 0, b"", version=2)),  # unknown version
        encode_frame(pack_frame(MessageType.PING, 4, 0, b"\x01")),  # malformed
        encode(Start(), 5, 0)[:-1] + b"\x00",  # fine: control case
        b"\x05\x01\x00",  # COBS error
        b"\x01" * 5000 + b"\x00",  # oversized
        encode_frame(b"EH\x01"),  # too short for a header
        encode(Ping(9), 6, 0)[:12] + b"\x00",  # truncated: valid COBS, shorter than a header
        encode(Configure(2, 500), 7, 0)[:30] + b"\x00",  # truncated: valid COBS, fails the CRC
    ]
    receiver = NativeReceiver(accept=HOST_TYPES)
    events = receiver.feed(good + b"".join(abuse) + good)
    assert isinstance(events[0], Received) and isinstance(events[-1], Received)
    c = receiver.counters
    assert (c.crc_errors, c.unknown_messages, c.version_errors, c.malformed_messages) == (2, 1, 1, 1)
    assert (c.framing_errors, c.oversized_frames, c.rx_frames) == (3, 1, 3)
    replies = [e.reply for e in events if isinstance(e, Rejected) and e.reply is not None]
    codes = [(r.code, r.offending_seq) for r in replies]
    expected = [ErrorCode.UNKNOWN_MESSAGE_TYPE, ErrorCode.UNSUPPORTED_VERSION, ErrorCode.MALFORMED_PAYLOAD]
    assert codes == list(zip(expected, (2, 3, 4), strict=True))


def test_rejected_events_carry_the_error() -> None:
    receiver = NativeReceiver(accept=HOST_TYPES)
    events = receiver.feed(encode_frame(pack_frame(MessageType.FEATURES, 1, 0, b"")))
    assert isinstance(events[0].error, UnknownMessageTypeError)
    events = receiver.feed(encode_frame(pack_frame(MessageType.PING, 1, 0, b"", version=0)))
    assert isinstance(events[0].error, UnsupportedVersionError)
    raw = bytearray(pack_frame(MessageType.START, 1, 0, b""))
    raw[0] ^= 1
    events = receiver.feed(encode_frame(bytes(raw)))
    assert isinstance(events[0].error, CrcError) and events[0].reply is None


def test_random_garbage_never_raises_and_valid_frames_after_it_decode() -> None:
    rng = np.random.default_rng(7)
    receiver = NativeReceiver()
    data, messages = _stream(count=8)
    for _ in range(100):
        garbage = rng.integers(0, 256, int(rng.integers(0, 2000)), dtype=np.uint8).tobytes()
        events = _feed_randomly(receiver, garbage + b"\x00" + data, rng)
        assert all(isinstance(e, Received | Rejected) for e in events)
        assert [e.message for e in events if isinstance(e, Received)][-8:] == messages
    assert receiver.counters.rx_frames >= 800


def test_frames_interleaved_with_garbage_without_delimiters() -> None:
    rng = np.random.default_rng(8)
    receiver = NativeReceiver()
    pieces, sent = [], []
    for i in range(200):
        pieces.append(encode(Ping(i), i, 0))
        sent.append(i)
        if rng.random() < 0.3:
            pieces.append(rng.integers(1, 256, int(rng.integers(1, 50)), dtype=np.uint8).tobytes())
    events = receiver.feed(b"".join(pieces))
    got = [e.message.nonce for e in events if isinstance(e, Received)]
    assert set(got) <= set(sent) and len(got) >= 120
    faults = [e for e in events if isinstance(e, Rejected)]
    assert len(got) + len(faults) <= 200 and all(isinstance(e.error, Exception | FramingFault) for e in faults)
    assert receiver.counters.lost_frames == max(got) - min(got) + 1 - len(got)


CAPS = Capability.FEATURES | Capability.ROI | Capability.BINOCULAR
INFO = DeviceInfo(1, 1, 640, 480, 30, 1000, 250, 2, CAPS, 4096, "test", "1.0")


@pytest.mark.parametrize(
    ("cfg", "code"),
    [
        (Configure(2, 500), None),
        (Configure(1, 30, EyeSelect.LEFT, StreamSelect.FEATURES, 10, 20, 300, 200), None),
        (Configure(3, 500), ErrorCode.INVALID_ARGUMENT),
        (Configure(0, 500), ErrorCode.INVALID_ARGUMENT),
        (Configure(2, 29), ErrorCode.INVALID_ARGUMENT),
        (Configure(2, 1001), ErrorCode.INVALID_ARGUMENT),  # above this device's maximum
        (Configure(2, 500, EyeSelect(0)), ErrorCode.INVALID_ARGUMENT),
        (Configure(2, 500, stream=StreamSelect(0)), ErrorCode.INVALID_ARGUMENT),
        (Configure(2, 500, stream=StreamSelect.FRAMES), ErrorCode.UNSUPPORTED),
        (Configure(2, 500, roi_x=400, roi_w=300, roi_h=10), ErrorCode.INVALID_ARGUMENT),
        (Configure(2, 500, roi_x=5), ErrorCode.INVALID_ARGUMENT),
    ],
)
def test_check_configure(cfg: Configure, code: ErrorCode | None) -> None:
    result = check_configure(cfg, INFO)
    assert (result if result is None else result[0]) == code


def test_default_configure_is_acceptable() -> None:
    cfg = default_configure(INFO)
    assert cfg == Configure(2, 250, EyeSelect.BOTH, StreamSelect.FEATURES)
    assert check_configure(cfg, INFO) is None


def _events_and_counters(receiver: NativeReceiver, pieces: list[bytes]) -> tuple[list, dict, tuple]:
    """Everything a receiver reports for `pieces` fed in turn: events (as comparable tuples), counters, framer's."""
    out = []
    for piece in pieces:
        for e in receiver.feed(piece):
            if isinstance(e, Received):
                out.append(("received", e.header, e.message, e.lost_before, e.out_of_order))
            else:
                out.append(("rejected", type(e.error).__name__, str(e.error), e.reply))
    f = receiver.framer
    return out, asdict(receiver.counters), (f.frames, f.cobs_errors, f.oversized, f.bytes_discarded, f.pending)


def _hostile_stream(rng: np.random.Generator) -> bytes:
    """Valid frames of every size among corrupted ones: flipped bytes (CRC), bad COBS, runs over the limit,
    an unknown type, another version, a bad payload length, empty runs, garbage without delimiters."""
    from eyehil.protocols import FrameChunk
    from eyehil.protocols.enums import Eye

    parts: list[bytes] = []
    seq = int(rng.integers(0, 2**32))
    for _ in range(int(rng.integers(5, 40))):
        kind = int(rng.integers(0, 12))
        size = int(rng.integers(0, 4075))
        chunk = FrameChunk(3, Eye.RIGHT, 1, 100, 60, 0, 0, 0, 2, 0, rng.integers(0, 256, min(size, 4074),
                                                                                   dtype=np.uint8).tobytes())
        frame = encode(chunk if kind % 2 else COMMANDS[kind % 4], seq, int(rng.integers(0, 2**63)))
        seq += int(rng.integers(1, 3))
        if kind == 2:  # a flipped byte
            i = int(rng.integers(1, len(frame) - 1))
            frame = frame[:i] + bytes([frame[i] ^ 0x5A or 1]) + frame[i + 1 :]
        elif kind == 3:  # bad COBS: a code byte that runs past the end
            frame = b"\xfe\x01\x02\x00"
        elif kind == 4:  # a run longer than any frame
            frame = rng.integers(1, 256, 5000, dtype=np.uint8).tobytes() + b"\x00"
        elif kind == 5:  # another version, an unknown type, a wrong length: good CRC and COBS
            raw = bytearray(pack_frame(0x90 + int(rng.integers(0, 3)), seq, 1, b"abc", version=2))
            frame = encode_frame(bytes(raw))
        elif kind == 6:
            frame = encode_frame(pack_frame(0x7E, seq, 1, b""))
        elif kind == 7:
            frame = b"\x00\x00" + frame
        elif kind == 8:
            frame = rng.integers(1, 256, int(rng.integers(1, 50)), dtype=np.uint8).tobytes() + frame
        parts.append(frame)
    return b"".join(parts)


@pytest.mark.skipif(not kernels.AVAILABLE, reason=f"compiled kernels unavailable: {kernels.REASON}")
@pytest.mark.parametrize("seed", range(40))
def test_the_batched_path_reports_what_the_per_frame_path_does(seed: int, monkeypatch) -> None:
    """A hostile stream cut at random places (single bytes, a frame's worth, 64 kB reads): the receiver that checks
    whole frames in one compiled call gives the per-frame path's events, counters and framer state, in order."""
    rng = np.random.default_rng(seed)
    stream = _hostile_stream(rng)
    cuts = np.sort(rng.choice(np.arange(1, len(stream)), size=min(len(stream) - 1, int(rng.integers(0, 30))),
                              replace=False))
    pieces = [stream[a:b] for a, b in itertools.pairwise([0, *cuts.tolist(), len(stream)])]
    kinds = set()
    for accept in (None, HOST_TYPES):
        fast = _events_and_counters(NativeReceiver(accept=accept), pieces)
        with monkeypatch.context() as patch:
            patch.setattr(kernels, "AVAILABLE", False)
            slow = _events_and_counters(NativeReceiver(accept=accept), pieces)
        assert fast == slow
        kinds |= {e[0] for e in fast[0]}
    assert kinds == {"received", "rejected"}  # the stream had both
