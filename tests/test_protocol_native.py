"""The native protocol: round trip of every message type, golden wire vectors, the exception tree."""

from __future__ import annotations

import binascii
import importlib.util
import struct
from pathlib import Path

import numpy as np
import pytest

from eyehil.protocols import (
    HOST_TYPES,
    MESSAGE_CLASSES,
    BadLengthError,
    BadMagicError,
    Configure,
    CrcError,
    ErrorCode,
    ErrorReply,
    Eye,
    EyeFeatures,
    Features,
    FrameChunk,
    FramingError,
    Glint,
    MalformedPayloadError,
    MessageType,
    PixelFormat,
    ProtocolError,
    PupilFlags,
    UnknownMessageTypeError,
    UnsupportedVersionError,
    cobs,
    decode,
    decode_wire,
    encode,
    encode_raw,
    error_reply_for,
    seq_gap,
)
from eyehil.protocols.crc import crc16_bitwise
from eyehil.protocols.header import HEADER, MAX_PAYLOAD, pack_frame, unpack_frame
from eyehil.protocols.images import ImageAssembler, split_image
from eyehil.protocols.messages import field_values
from eyehil.protocols.stream import NativeReceiver

GOLDEN = Path(__file__).parent / "golden"


def _load_canonical() -> dict:
    """CANONICAL from tests/golden/make_golden.py, loaded by path (tests is not a package)."""
    spec = importlib.util.spec_from_file_location("eyehil_make_golden", GOLDEN / "make_golden.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module.CANONICAL


CANONICAL = _load_canonical()


def _read_hex(path: Path) -> bytes:
    lines = path.read_text(encoding="utf-8").splitlines()
    return bytes.fromhex(" ".join(ln for ln in lines if not ln.startswith("#")))


def test_canonical_set_covers_every_message_type() -> None:
    assert {m.TYPE for m, _, _ in CANONICAL.values()} == set(MessageType) == set(MESSAGE_CLASSES)


@pytest.mark.parametrize("name", sorted(CANONICAL))
def test_round_trip_every_message_type(name: str) -> None:
    message, seq, timestamp_us = CANONICAL[name]
    header, decoded = decode_wire(encode(message, seq, timestamp_us))
    assert decoded == message and type(decoded) is type(message)
    assert (header.msg_type, header.seq, header.timestamp_us, header.version) == (message.TYPE, seq, timestamp_us, 1)


@pytest.mark.parametrize("name", sorted(CANONICAL))
def test_golden_vector_byte_for_byte(name: str) -> None:
    message, seq, timestamp_us = CANONICAL[name]
    golden = _read_hex(GOLDEN / f"{name}.hex")
    assert encode(message, seq, timestamp_us) == golden, "wire format changed: see tests/golden/make_golden.py"
    assert decode_wire(golden)[1] == message


def test_features_one_eye_two_glints_is_74_bytes_on_the_wire() -> None:
    message, seq, timestamp_us = CANONICAL["features"]
    assert len(message.eyes) == 1 and len(message.eyes[0].glints) == 2
    assert len(encode_raw(message, seq, timestamp_us)) == 72
    assert len(encode(message, seq, timestamp_us)) == 74


def test_header_layout_is_18_bytes_little_endian() -> None:
    raw = encode_raw(CANONICAL["ping"][0], 0x01020304, 0x0A0B0C0D0E0F1011)
    assert HEADER.size == 18
    assert raw[:18] == bytes.fromhex("4548 01 01 04030201 11100f0e0d0c0b0a 0400")
    assert raw[-2:] == struct.pack("<H", binascii.crc_hqx(raw[:-2], 0xFFFF))


def _random_features(rng: np.random.Generator) -> Features:
    f32 = lambda: float(np.float32(rng.uniform(-1e3, 1e3)))  # noqa: E731
    u8 = lambda: int(rng.integers(0, 256))  # noqa: E731
    eyes = []
    for eye in rng.permutation([Eye.RIGHT, Eye.LEFT])[: rng.integers(0, 3)]:
        n_glints = rng.integers(0, 9)
        glints = tuple(Glint(u8(), f32(), f32(), u8()) for _ in range(n_glints))
        eyes.append(EyeFeatures(Eye(eye), u8(), f32(), f32(), f32(), f32(), f32(), f32(), glints))
    return Features(int(rng.integers(0, 2**32)), tuple(eyes))


def test_features_randomised_round_trip() -> None:
    rng = np.random.default_rng(5)
    for _ in range(300):
        message = _random_features(rng)
        seq, ts = int(rng.integers(0, 2**32)), int(rng.integers(0, 2**63))
        assert decode_wire(encode(message, seq, ts))[1] == message


def test_sequence_numbers_wrap_and_gaps_are_detected() -> None:
    header, _ = decode_wire(encode(CANONICAL["start"][0], 2**32 + 5, 0))
    assert header.seq == 5
    assert seq_gap(0xFFFFFFFF, 0) == 0
    assert seq_gap(0xFFFFFFFE, 2) == 3
    assert seq_gap(10, 10) == -1 and seq_gap(10, 3) < 0


def _refuse(frame: bytes, exc_type: type[ProtocolError], **kwargs) -> ProtocolError:
    with pytest.raises(exc_type) as info:
        decode(frame, **kwargs)
    return info.value


def test_bad_crc_is_refused_without_reply() -> None:
    raw = bytearray(encode_raw(CANONICAL["configure"][0], 9, 0))
    raw[20] ^= 0x10
    exc = _refuse(bytes(raw), CrcError)
    assert error_reply_for(exc) is None


def test_too_short_frame_is_a_framing_error() -> None:
    _refuse(b"EH\x01\x02", FramingError)


def test_bad_magic_is_refused_without_reply() -> None:
    raw = pack_frame(MessageType.GET_INFO, 1, 0, b"")
    forged = b"XY" + raw[2:-2]
    exc = _refuse(pack_frame_crc(forged), BadMagicError)
    assert error_reply_for(exc) is None


def pack_frame_crc(body: bytes) -> bytes:
    """`body` with a correct CRC trailer appended."""
    return body + struct.pack("<H", binascii.crc_hqx(body, 0xFFFF))


def test_unknown_version_gets_error_with_offending_seq() -> None:
    exc = _refuse(pack_frame(MessageType.GET_INFO, 77, 0, b"", version=9), UnsupportedVersionError)
    reply = error_reply_for(exc)
    assert (reply.code, reply.offending_seq, reply.offending_type) == (ErrorCode.UNSUPPORTED_VERSION, 77, 0x02)


def test_unknown_type_gets_error() -> None:
    exc = _refuse(pack_frame(0x55, 12, 0, b"\x01\x02"), UnknownMessageTypeError)
    reply = error_reply_for(exc)
    assert (reply.code, reply.offending_seq, reply.offending_type) == (ErrorCode.UNKNOWN_MESSAGE_TYPE, 12, 0x55)


def test_device_refuses_device_to_host_types() -> None:
    raw = encode_raw(CANONICAL["features"][0], 3, 0)
    _refuse(raw, UnknownMessageTypeError, accept=HOST_TYPES)
    assert decode(encode_raw(CANONICAL["start"][0], 3, 0), accept=HOST_TYPES)[1] == CANONICAL["start"][0]


def test_bad_length_field_is_malformed() -> None:
    body = bytearray(encode_raw(CANONICAL["ping"][0], 4, 0)[:-2])
    body[16] = 5  # payload_len says 5, the frame holds 4
    exc = _refuse(pack_frame_crc(bytes(body)), BadLengthError)
    assert isinstance(exc, MalformedPayloadError) and error_reply_for(exc).code == ErrorCode.MALFORMED_PAYLOAD


@pytest.mark.parametrize(
    ("msg_type", "payload"),
    [
        (MessageType.PING, b"\x01\x02\x03"),  # 3 bytes for <I
        (MessageType.START, b"\x00"),  # empty payload expected
        (MessageType.STATUS, bytes([7]) + bytes(52)),  # unknown DeviceState
        (MessageType.FEATURES, struct.pack("<IB", 1, 1) + bytes(10)),  # truncated eye record
        (MessageType.FEATURES, struct.pack("<IB", 1, 0) + b"\x00"),  # trailing byte
        (MessageType.FEATURES, struct.pack("<IB", 1, 1) + struct.pack("<BBffffffB", 2, 1, *[0.0] * 6, 0)),  # Eye.BOTH
        (MessageType.ERROR, struct.pack("<BIB", 5, 1, 3) + b"\x02\xff\xfe"),  # not UTF-8
        (MessageType.ERROR, struct.pack("<BIB", 5, 1, 3) + b"\x09abc"),  # string runs past the end
        (MessageType.DEVICE_INFO, bytes(10)),  # too short
        (MessageType.FRAME_CHUNK, struct.pack("<IBBHHHHHHI", 1, 0, 1, 2, 2, 0, 0, 0, 1, 0) + bytes(5)),  # > 4 px
        (MessageType.FRAME_CHUNK, struct.pack("<IBBHHHHHHI", 1, 0, 9, 2, 2, 0, 0, 0, 1, 0)),  # pixel format 9
        (MessageType.FRAME_CHUNK, struct.pack("<IBBHHHHHHI", 1, 0, 1, 2, 2, 0, 0, 1, 1, 0)),  # index >= count
    ],
)
def test_malformed_payloads_are_refused_with_seq(msg_type: int, payload: bytes) -> None:
    exc = _refuse(pack_frame(msg_type, 42, 0, payload), MalformedPayloadError)
    assert (exc.seq, exc.msg_type) == (42, msg_type)
    assert error_reply_for(exc).code == ErrorCode.MALFORMED_PAYLOAD


def test_encoder_refuses_values_that_do_not_fit() -> None:
    configure, _, _ = CANONICAL["configure"]
    with pytest.raises(ValueError):
        encode(configure, 0, -1)  # negative timestamp
    with pytest.raises(ValueError):
        encode(Configure(leds=300, rate_hz=500), 0, 0)
    with pytest.raises(ValueError):
        encode(ErrorReply(ErrorCode.BUSY, 1, 3, "x" * 65), 0, 0)
    with pytest.raises(ValueError):
        pack_frame(MessageType.FRAME_CHUNK, 0, 0, bytes(MAX_PAYLOAD + 1))


def test_largest_frame_chunk_fits() -> None:
    data = bytes(range(256)) * 15 + bytes(range(234))  # 4074 bytes: MAX_PAYLOAD - 22
    chunk = FrameChunk(1, Eye.BOTH, PixelFormat.MONO8, 4074, 1, 0, 0, 0, 1, 0, data)
    assert decode_wire(encode(chunk, 0, 0))[1] == chunk


def test_unpack_frame_checks_crc_before_anything_else() -> None:
    raw = bytearray(pack_frame(0x55, 1, 0, b"", version=9))
    raw[-1] ^= 1
    with pytest.raises(CrcError):
        unpack_frame(bytes(raw))


def test_message_constructors_coerce_and_validate() -> None:
    eye = EyeFeatures(1, 1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, [Glint(0, 1.0, 2.0)])
    assert eye.eye is Eye.LEFT and eye.flags is PupilFlags.DETECTED and isinstance(eye.glints, tuple)
    with pytest.raises(ValueError):
        EyeFeatures(Eye.BOTH, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _reference_wire(chunk: FrameChunk, seq: int, timestamp_us: int) -> bytes:
    """A FRAME_CHUNK's wire bytes built from the layout, field by field, with the bitwise CRC and the reference COBS."""
    payload = struct.pack("<IBBHHHHHHI", *field_values(chunk)[:-1]) + chunk.data
    body = HEADER.pack(0x4845, 1, 0x91, seq % 2**32, timestamp_us, len(payload)) + payload
    return cobs.encode_reference(body + struct.pack("<H", crc16_bitwise(body))) + b"\x00"


def test_image_chunks_are_the_reference_bytes_on_the_wire_and_decode_back() -> None:
    rng = np.random.default_rng(14)
    images = [rng.integers(1, 256, (240, 320)), rng.integers(0, 256, (240, 320)), np.zeros((60, 70)),
              np.full((17, 254), 7), rng.integers(0, 2, (33, 508))]  # fmt: skip
    seqs = [0, 1, 0x01000000, 0xFFFFFFFF, 2**32 + 5, 0x00FF00FF, 0x12345678]
    receiver, assembler, wire = NativeReceiver(), ImageAssembler(), b""
    for n, pixels in enumerate(images):
        chunks = split_image(n, Eye(n % 3), pixels.astype(np.uint8), (n, 2 * n))
        for k, chunk in enumerate(chunks):
            seq, timestamp_us = seqs[(n + k) % len(seqs)], int(rng.integers(0, 2**63))
            wire_k = encode(chunk, seq, timestamp_us)
            assert wire_k == _reference_wire(chunk, seq, timestamp_us), (n, k)
            assert chunk.to_payload() == struct.pack("<IBBHHHHHHI", *field_values(chunk)[:-1]) + chunk.data
            wire += wire_k
    done = [assembler.add(e.message) for e in receiver.feed(wire)]
    assert [d.pixels.tobytes() for d in done if d is not None] == [p.astype(np.uint8).tobytes() for p in images]
    assert receiver.counters.rx_frames == len(done) and assembler.complete == len(images)


def test_frame_chunk_coerces_numbers_to_enums_like_the_enum_constructors() -> None:
    chunk = FrameChunk(1, np.uint8(2), 2, 2, 2, 0, 0, 0, 1, 0, bytearray(8))
    assert chunk.eye is Eye.BOTH and chunk.pixel_format is PixelFormat.MONO16 and type(chunk.data) is bytes
    assert FrameChunk(1, True, 1.0, 2, 2, 0, 0, 0, 1, 0, memoryview(b"ab")).eye is Eye(True) is Eye.LEFT
    for eye, pixel_format in ((3, 1), (-1, 1), ("0", 1), ([0], 1), (0, 0), (0, 3), (0, None), (0, [1])):
        with pytest.raises(ValueError):
            FrameChunk(1, eye, pixel_format, 2, 2, 0, 0, 0, 1, 0, b"")


def test_header_message_type_is_the_enum_member_or_the_unknown_number() -> None:
    header, _ = unpack_frame(pack_frame(0x91, 1, 0, FrameChunk(1, 0, 1, 1, 1, 0, 0, 0, 1, 0, b"x").to_payload()))
    assert header.msg_type is MessageType.FRAME_CHUNK
    for number in (0x00, 0x55, 0x92, 0xFF):
        header, _ = unpack_frame(pack_frame(number, 1, 0, b""))
        assert header.msg_type == number and type(header.msg_type) is int
