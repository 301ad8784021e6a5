"""COBS, CRC and the frame layer: known answers, round trips, and a decoder under abuse that never raises."""

from __future__ import annotations

import binascii
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyehil.protocols import cobs, kernels
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
from eyehil.protocols.header import MAX_PAYLOAD, pack_frame, wire_frame

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


def _cobs_edge_cases() -> list[bytes]:
    """Lengths and zero placements where the fast paths change branch: empty, all zeros, runs of 253..255, 508,
    509 and 64 * 254 (one decoded run) +- 1 non-zero bytes, alone, after or before a zero, and data ending in zeros."""
    cases = [b"", b"\x00", b"\x00" * 2, bytes(254), bytes(1000)]
    for n in (1, 253, 254, 255, 507, 508, 509, 64 * 254 - 1, 64 * 254, 64 * 254 + 1, 130 * 254):
        run = bytes(1 + k % 255 for k in range(n))
        cases += [run, run + b"\x00", b"\x00" + run, run + b"\x00" + run, run + b"\x00\x00", b"\x11\x00" + run]
    return cases


def _random_cobs_data(rng: np.random.Generator, count: int) -> list[bytes]:
    """Random strings of 0..1800 bytes, their zero density from none to all (as often none: long runs)."""
    out = []
    for _ in range(count):
        n = int(rng.integers(0, 1800))
        zeros = rng.random() ** 3 if rng.random() < 0.7 else 0.0
        out.append(np.where(rng.random(n) < zeros, 0, rng.integers(1, 256, n)).astype(np.uint8).tobytes())
    return out


def _decoded_or_error(decode, encoded: bytes) -> bytes | str:
    """What a COBS decoder makes of `encoded`: the bytes, or its error's message."""
    try:
        return decode(encoded)
    except CobsDecodeError as exc:
        return f"error: {exc}"


def _compiled_decode(encoded: bytes) -> bytes:
    """The kernel alone, with `cobs.decode`'s contract: invalid strings raise the reference's error."""
    out = kernels.cobs_decode(encoded)
    return cobs.decode_reference(encoded) if out is None else out


NO_KERNELS = pytest.mark.skipif(not kernels.AVAILABLE, reason=f"compiled kernels unavailable: {kernels.REASON}")
#: (encode, decode) of each fast path: what `cobs.encode`/`decode` run (the kernels where built), the Python fast
#: paths, and the compiled kernels themselves.
FAST_PATHS = [pytest.param(cobs.encode, cobs.decode, id="public"),
              pytest.param(cobs.encode_python, cobs.decode_python, id="python"),
              pytest.param(lambda d: kernels.cobs_encode(d), _compiled_decode, id="compiled", marks=NO_KERNELS)]


def test_the_compiled_kernels_are_in_use_where_a_compiler_is() -> None:
    import shutil

    if shutil.which("cc") is None:
        pytest.skip("no C compiler here")
    assert kernels.AVAILABLE or "EYEHIL_PURE_PYTHON" in kernels.REASON, kernels.REASON


@pytest.mark.parametrize(("encode", "decode"), FAST_PATHS)
def test_cobs_fast_paths_give_the_references_bytes(encode, decode) -> None:
    for data in _cobs_edge_cases() + _random_cobs_data(np.random.default_rng(5), 1500):
        encoded = cobs.encode_reference(data)
        assert encode(data) == encoded
        assert encode(bytearray(data)) == encode(memoryview(data)) == encoded
        assert decode(encoded) == cobs.decode_reference(encoded) == data
        assert decode(bytearray(encoded)) == data
        assert type(encode(data)) is bytes and type(decode(encoded)) is bytes


@pytest.mark.parametrize(("encode", "decode"), FAST_PATHS)
def test_cobs_decoder_refuses_what_the_reference_refuses_with_the_same_message(encode, decode) -> None:
    rng = np.random.default_rng(6)
    bad = 0
    for data in _cobs_edge_cases() + _random_cobs_data(rng, 600):
        encoded = cobs.encode_reference(data)
        for _ in range(4):  # overwrite a byte (sometimes with 0x00 or 0xFF), then maybe truncate
            mutated = bytearray(encoded)
            k = int(rng.integers(0, len(mutated)))
            mutated[k] = int(rng.choice([0, 0xFF, int(rng.integers(1, 256))]))
            if rng.random() < 0.5:
                del mutated[int(rng.integers(1, len(mutated) + 1)) :]
            expected = _decoded_or_error(cobs.decode_reference, bytes(mutated))
            assert _decoded_or_error(decode, bytes(mutated)) == expected
            bad += isinstance(expected, str)
    for count in (1, 2, 63, 64, 65, 130):  # runs of 0xFF blocks, the last one truncated by 1 or 254 bytes
        for short in (1, 254):
            src = ((b"\xff" + bytes(range(1, 255))) * count)[:-short]
            assert _decoded_or_error(decode, src) == _decoded_or_error(cobs.decode_reference, src)
    assert bad > 500  # the mutations did reach the error paths


@pytest.mark.parametrize(("encode", "decode"), FAST_PATHS)
@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=2000))
def test_cobs_fast_paths_match_the_reference_property(encode, decode, data: bytes) -> None:
    encoded = encode(data)
    assert encoded == cobs.encode_reference(data)
    assert decode(encoded) == data
    assert _decoded_or_error(decode, data) == _decoded_or_error(cobs.decode_reference, data)


@pytest.mark.parametrize(("encode", "decode"), FAST_PATHS)
@settings(max_examples=200, deadline=None)
@given(data=st.lists(st.sampled_from([b"\x00", b"\x01", bytes(range(1, 254)), bytes(range(1, 255)),
                                      bytes(range(1, 256))]), max_size=12).map(b"".join))
def test_cobs_fast_paths_at_the_block_boundaries_property(encode, decode, data: bytes) -> None:
    """Runs of 253, 254 and 255 non-zero bytes between zeros: where a 0xFF block starts, ends or is followed by none."""
    encoded = encode(data)
    assert encoded == cobs.encode_reference(data)
    assert decode(encoded) == data


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


@NO_KERNELS
@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=300), value=st.integers(0, 0xFFFF), cut=st.integers(0, 300))
def test_crc_kernel_matches_binascii_property(data: bytes, value: int, cut: int) -> None:
    """Every length (the 8-byte slices and the bytes after them) and any starting register."""
    assert kernels.crc16(data, value) == binascii.crc_hqx(data, value)
    assert kernels.crc16(bytearray(data), value) == kernels.crc16(memoryview(data), value) == crc16(data, value)
    assert kernels.crc16(data[cut:], kernels.crc16(data[:cut], value)) == binascii.crc_hqx(data, value)


@NO_KERNELS
def test_the_kernels_frame_limit_is_the_protocols() -> None:
    assert kernels.MAX_FRAME == MAX_FRAME_SIZE


@pytest.mark.parametrize("compiled", [pytest.param(True, marks=NO_KERNELS, id="compiled"),
                                      pytest.param(False, id="python")])
@settings(max_examples=300, deadline=None)
@given(msg_type=st.integers(0, 255), seq=st.integers(0, 2**33), timestamp=st.integers(0, 2**64 - 1),
       payload=st.one_of(st.binary(max_size=600), st.binary(min_size=MAX_PAYLOAD - 300, max_size=MAX_PAYLOAD)))
def test_wire_frame_is_pack_frame_then_encode_frame_property(compiled: bool, msg_type: int, seq: int,
                                                               timestamp: int, payload: bytes) -> None:
    """The fused encode (CRC, COBS and delimiter in one kernel call) gives the two-step path's bytes, up to the
    largest payload; the Python path when the kernels are switched off gives them too."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(kernels, "AVAILABLE", compiled)
        wire = wire_frame(msg_type, seq, timestamp, payload)
    assert wire == encode_frame(pack_frame(msg_type, seq, timestamp, payload))
    assert type(wire) is bytes and wire.endswith(b"\x00") and wire.count(0) == 1


@pytest.mark.parametrize("compiled", [pytest.param(True, marks=NO_KERNELS, id="compiled"),
                                      pytest.param(False, id="python")])
def test_wire_frame_refuses_what_pack_frame_refuses(compiled: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernels, "AVAILABLE", compiled)
    with pytest.raises(ValueError, match="MAX_PAYLOAD"):
        wire_frame(0x91, 1, 0, bytes(MAX_PAYLOAD + 1))
    with pytest.raises(ValueError, match="out of range"):
        wire_frame(0x91, 1, -1, b"")


@NO_KERNELS
def test_frame_encode_refuses_a_frame_over_the_limit() -> None:
    assert kernels.frame_encode(bytes(MAX_FRAME_SIZE - 2)).endswith(b"\x00")
    with pytest.raises(ValueError, match="exceeds"):
        kernels.frame_encode(bytes(MAX_FRAME_SIZE - 1))


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


def _counters(decoder: FrameDecoder) -> tuple[int, int, int, int, int]:
    return decoder.frames, decoder.cobs_errors, decoder.oversized, decoder.bytes_discarded, decoder.pending


class _BufferedOnly(FrameDecoder):
    """The decoder without its fast path: every frame passes through the buffer (as before the fast path)."""

    def _whole(self, encoded: bytes, events: list) -> None:
        self._accumulate(encoded, events)
        self._finish(events)


def test_whole_frames_in_one_feed_give_the_events_of_the_buffered_path() -> None:
    """Frames wholly inside one `feed` skip the buffer; events and counters are those of the buffered path."""
    rng = np.random.default_rng(7)
    pieces = [encode_frame(f) for f in _frames(rng, 40)]
    pieces += [b"\x05\x11\x00", b"\x03\x11", b"\x00", b"\x01" * (MAX_ENCODED_SIZE + 1) + b"\x00"]  # COBS, too long
    pieces += [b"\x00" * 3, encode_frame(bytes(MAX_FRAME_SIZE)), b"\xff" * 300 + b"\x00"]  # largest, truncated run
    pieces += [cobs.encode(bytes(40)) + b"\x00", rng.integers(0, 256, 5000, dtype=np.uint8).tobytes()]  # garbage
    order = rng.permutation(len(pieces))
    stream = b"".join(pieces[k] for k in order) + b"\x00" + encode_frame(b"last") + b"\x07\x01"  # a partial frame
    for max_frame in (MAX_FRAME_SIZE, 30):  # 30: valid COBS that decodes too long is the other oversized fault
        fast, buffered = FrameDecoder(max_frame), _BufferedOnly(max_frame)
        expected = buffered.feed(stream)
        assert fast.feed(stream) == expected and _counters(fast) == _counters(buffered)
        kinds = {e.kind for e in expected if isinstance(e, FramingFault)}
        assert kinds == {FaultKind.COBS, FaultKind.OVERSIZED} and expected[-1] == b"last" and fast.pending == 2
        for trial in range(3):  # the same stream cut at random places
            fast, buffered = FrameDecoder(max_frame), _BufferedOnly(max_frame)
            cut = _feed_in_pieces(fast, stream, np.random.default_rng(trial))
            assert cut == _feed_in_pieces(buffered, stream, np.random.default_rng(trial))
            assert _counters(fast) == _counters(buffered) and cut[-1] == b"last"


@NO_KERNELS
@settings(max_examples=200, deadline=None)
@given(size=st.integers(0, 20_000), value=st.integers(0, 0xFFFF), seed=st.integers(0, 2**32 - 1),
       cut=st.integers(0, 20_000))
def test_long_crcs_match_binascii_property(size: int, value: int, seed: int, cut: int) -> None:
    """From 64 bytes on the kernel folds blocks (`kernels.FOLDING`, where the processor multiplies carry-less): every
    length (whole 64-byte groups, 16-byte blocks and a tail), any starting register, continued at any cut."""
    data = np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8).tobytes()
    cut = min(cut, size)
    assert kernels.crc16(data, value) == binascii.crc_hqx(data, value)
    assert kernels.crc16(data[cut:], kernels.crc16(data[:cut], value)) == binascii.crc_hqx(data, value)


@NO_KERNELS
def test_crc_of_structured_data_over_the_folding_sizes() -> None:
    """Zeros, ones and patterns (carries and reductions the random data may miss), at the lengths around each
    block boundary of the folding."""
    for n in [63, 64, 65, 79, 80, 127, 128, 129, 191, 192, 255, 256, 257, 4114, 4116, 65536]:
        for data in (bytes(n), b"\xff" * n, bytes(range(256)) * (n // 256) + bytes(range(n % 256)),
                     (b"\x80" + bytes(15)) * (n // 16) + b"\x01" * (n % 16)):
            for value in (0, 0xFFFF, 0x8000, 0x0001):
                assert kernels.crc16(data, value) == binascii.crc_hqx(data, value), (n, value)
