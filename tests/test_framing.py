"""COBS, CRC and the frame layer: known answers, round trips, and a decoder under abuse that never raises."""

from __future__ import annotations

import binascii
import itertools

import numpy as np
import pytest

from eyehil.protocols import cobs
from eyehil.protocols.crc import CRC16_CHECK, crc16, crc16_bitwise
from eyehil.protocols.errors import CobsDecodeError, FramingError
from eyehil.protocols.framing import (
    MAX_ENCODED_SIZE,
    MAX_FRAME_SIZE,
    FaultKind,
    FrameDecoder,
    FramingFault,
    encode_frame,
)

# Written from the definition (Cheshire & Baker 1999), the examples also listed on Wikipedia's COBS page.
COBS_KNOWN = [
    ("", "01"),
    ("00", "01 01"),
    ("00 00", "01 01 01"),
    ("00 11 00", "01 02 11 01"),
    ("11 22 00 33", "03 11 22 02 33"),
    ("11 22 33 44", "05 11 22 33 44"),
    ("11 00 00 00", "02 11 01 01 01"),
]


def _long_cases() -> list[tuple[bytes, bytes]]:
    """The 254/255-byte examples, where the 0xFF code (no implied zero) appears."""
    run = bytes(range(1, 255))  # 01..FE, 254 bytes
    return [
        (run, b"\xff" + run),
        (b"\x00" + run, b"\x01\xff" + run),
        (run + b"\xff", b"\xff" + run + b"\x02\xff"),
        (bytes(range(2, 256)) + b"\x00\x01", b"\xff" + bytes(range(2, 256)) + b"\x01\x02\x01"),
        (bytes(range(3, 256)) + b"\x00\x01\x02", b"\xfe" + bytes(range(3, 256)) + b"\x03\x01\x02"),
    ]


@pytest.mark.parametrize(("plain", "encoded"), COBS_KNOWN)
def test_cobs_known_answers(plain: str, encoded: str) -> None:
    assert cobs.encode(bytes.fromhex(plain)) == bytes.fromhex(encoded)
    assert cobs.decode(bytes.fromhex(encoded)) == bytes.fromhex(plain)


@pytest.mark.parametrize("case", range(5))
def test_cobs_long_known_answers(case: int) -> None:
    plain, encoded = _long_cases()[case]
    assert cobs.encode(plain) == encoded
    assert cobs.decode(encoded) == plain


def test_cobs_decoder_accepts_the_papers_trailing_block() -> None:
    run = bytes(range(1, 255))
    assert cobs.decode(b"\xff" + run + b"\x01") == run


def test_cobs_round_trip_random() -> None:
    rng = np.random.default_rng(1)
    for _ in range(500):
        n = int(rng.integers(0, 1200))
        zeros = rng.random()  # vary the density of zero bytes from none to all
        data = np.where(rng.random(n) < zeros, 0, rng.integers(1, 256, n)).astype(np.uint8).tobytes()
        enc = cobs.encode(data)
        assert 0 not in enc
        assert len(enc) <= cobs.max_encoded_size(n)
        assert cobs.decode(enc) == data


@pytest.mark.parametrize("bad", ["", "00", "05 11 22", "03 11 00", "02 11 00 01"])
def test_cobs_decode_errors(bad: str) -> None:
    with pytest.raises(CobsDecodeError):
        cobs.decode(bytes.fromhex(bad))
    assert issubclass(CobsDecodeError, FramingError)


def test_crc_known_answer() -> None:
    assert crc16(b"123456789") == CRC16_CHECK == 0x29B1
    assert crc16_bitwise(b"123456789") == 0x29B1
    assert crc16(b"") == 0xFFFF


def test_crc_fast_path_matches_reference_and_binascii() -> None:
    rng = np.random.default_rng(2)
    for n in (1, 2, 17, 255, 1000):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert crc16(data) == crc16_bitwise(data) == binascii.crc_hqx(data, 0xFFFF)
        assert crc16(data[n // 2 :], crc16(data[: n // 2])) == crc16(data)


def test_encode_frame_adds_one_delimiter_and_refuses_oversized() -> None:
    wire = encode_frame(b"\x00abc\x00")
    assert wire.count(0) == 1 and wire.endswith(b"\x00")
    assert len(encode_frame(bytes(MAX_FRAME_SIZE))) == MAX_FRAME_SIZE + 2
    with pytest.raises(FramingError):
        encode_frame(bytes(MAX_FRAME_SIZE + 1))


def _frames(rng: np.random.Generator, count: int) -> list[bytes]:
    """Random frames with plenty of zero bytes, sizes 1..600."""
    sizes = rng.integers(1, 600, count)
    return [np.where(rng.random(n) < 0.2, 0, rng.integers(0, 256, n)).astype(np.uint8).tobytes() for n in sizes]


def _feed_in_pieces(decoder: FrameDecoder, stream: bytes, rng: np.random.Generator) -> list:
    """Feed `stream` cut at random boundaries (including 1-byte and empty pieces); return all events."""
    cuts = np.sort(rng.integers(0, len(stream) + 1, len(stream) // 7 + 1))
    bounds = [0, *cuts.tolist(), len(stream)]
    events = []
    for a, b in itertools.pairwise(bounds):
        events += decoder.feed(stream[a:b])
    return events


def test_decoder_reassembles_frames_split_at_random_boundaries() -> None:
    rng = np.random.default_rng(3)
    frames = _frames(rng, 200)
    stream = b"".join(encode_frame(f) for f in frames)
    for trial in range(5):
        decoder = FrameDecoder()
        assert _feed_in_pieces(decoder, stream, np.random.default_rng(trial)) == frames
        assert decoder.frames == 200 and decoder.pending == 0


def test_decoder_ignores_empty_frames() -> None:
    decoder = FrameDecoder()
    assert decoder.feed(b"\x00\x00" + encode_frame(b"x") + b"\x00") == [b"x"]
    assert decoder.cobs_errors == decoder.oversized == 0


def test_decoder_survives_random_bytes_and_resynchronises() -> None:
    rng = np.random.default_rng(4)
    decoder = FrameDecoder()
    for _ in range(50):
        garbage = rng.integers(0, 256, int(rng.integers(1, 3000)), dtype=np.uint8).tobytes()
        events = _feed_in_pieces(decoder, garbage, rng)
        assert all(isinstance(e, bytes | FramingFault) for e in events)
        assert decoder.pending <= decoder.max_encoded
        assert decoder.feed(b"\x00" + encode_frame(b"sync"))[-1] == b"sync"


def test_garbage_without_delimiter_costs_only_the_next_frame() -> None:
    decoder = FrameDecoder()
    events = decoder.feed(b"\x07\x01\x02" + encode_frame(b"lost") + encode_frame(b"kept"))
    assert events[-1] == b"kept"
    assert b"lost" not in events


def test_truncated_frame_is_reported_and_the_next_one_decoded() -> None:
    decoder = FrameDecoder()
    wire = encode_frame(bytes(range(1, 40)))
    events = decoder.feed(wire[:10] + b"\x00" + encode_frame(b"next"))
    assert isinstance(events[0], FramingFault) and events[0].kind is FaultKind.COBS
    assert events[1:] == [b"next"] and decoder.cobs_errors == 1


def test_oversized_frame_is_dropped_counted_and_memory_stays_bounded() -> None:
    decoder = FrameDecoder()
    events = []
    for _ in range(100):  # 100 kB without a delimiter
        events += decoder.feed(b"\x01" * 1000)
        assert decoder.pending <= MAX_ENCODED_SIZE
    events += decoder.feed(b"\x00" + encode_frame(b"after"))
    faults = [e for e in events if isinstance(e, FramingFault)]
    assert len(faults) == 1 and faults[0].kind is FaultKind.OVERSIZED
    assert events[-1] == b"after" and decoder.oversized == 1
    assert decoder.bytes_discarded == 100_000


def test_small_max_frame_drops_valid_cobs_that_decodes_too_long() -> None:
    decoder = FrameDecoder(max_frame=10)
    events = decoder.feed(encode_frame(bytes(11), max_frame=100) + encode_frame(bytes(10)))
    assert isinstance(events[0], FramingFault) and events[1] == bytes(10)
    assert decoder.oversized == 1


def test_reset_forgets_the_partial_frame() -> None:
    decoder = FrameDecoder()
    decoder.feed(encode_frame(b"partial")[:-3])
    decoder.reset()
    assert decoder.pending == 0
    assert decoder.feed(encode_frame(b"whole")) == [b"whole"]
