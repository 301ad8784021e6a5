"""The frame layout of the eyehil native protocol: header, payload, CRC trailer; message type numbers.

A frame (before COBS) is, little-endian throughout::

    offset size  field
    0      2     magic           0x4845 (the bytes b"EH")
    2      1     version         protocol version of this frame (1)
    3      1     type            MessageType
    4      4     seq             uint32 sequence number, per direction, wraps 0xFFFFFFFF -> 0
    8      8     timestamp_us    uint64 sender's monotonic clock, microseconds
    16     2     payload_len     uint16, 0..MAX_PAYLOAD
    18     n     payload
    18+n   2     crc             CRC-16/CCITT-FALSE over bytes [0, 18 + n), low byte first

The header layout and the CRC trailer are frozen for every protocol version, so that a receiver can
always check the CRC, read version, type and seq of a frame it cannot parse, and refuse it by number.
`unpack_frame` checks, in order: size, CRC, magic, version, payload length. `pack_frame` builds a frame;
`wire_frame` builds its wire bytes (COBS and delimiter, `eyehil.protocols.framing`) in the same step.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from eyehil.protocols import kernels
from eyehil.protocols.crc import CRC_SIZE, crc16
from eyehil.protocols.errors import BadLengthError, BadMagicError, CrcError, FramingError, UnsupportedVersionError
from eyehil.protocols.framing import MAX_FRAME_SIZE, encode_frame

MAGIC = 0x4845
PROTOCOL_VERSION = 1
SUPPORTED_VERSIONS = frozenset({PROTOCOL_VERSION})
HEADER = struct.Struct("<HBBIQH")
HEADER_SIZE = HEADER.size  # 18
MIN_FRAME_SIZE = HEADER_SIZE + CRC_SIZE  # 20
MAX_PAYLOAD = MAX_FRAME_SIZE - MIN_FRAME_SIZE  # 4096
SEQ_MODULUS = 1 << 32
_CRC = struct.Struct("<H")


class MessageType(IntEnum):
    """Message type numbers: 0x01-0x3F host -> device, 0x80-0xBF device -> host."""

    PING = 0x01
    GET_INFO = 0x02
    CONFIGURE = 0x03
    START = 0x04
    STOP = 0x05
    GET_STATUS = 0x06
    STIMULUS = 0x10
    PONG = 0x81
    DEVICE_INFO = 0x82
    STATUS = 0x86
    FEATURES = 0x90
    FRAME_CHUNK = 0x91
    ACK = 0xA0
    ERROR = 0xA1

    @property
    def from_host(self) -> bool:
        """True for the types a host sends to a device."""
        return self < 0x80


@dataclass(frozen=True, slots=True)
class Header:
    """A decoded header: `msg_type` is a `MessageType` when known, else the raw number."""

    version: int
    msg_type: int
    seq: int
    timestamp_us: int
    payload_len: int


def pack_frame(msg_type: int, seq: int, timestamp_us: int, payload: bytes, version: int = PROTOCOL_VERSION) -> bytes:
    """Header + payload + CRC (not yet COBS-encoded); `seq` is taken modulo 2**32."""
    head = _pack_header(msg_type, seq, timestamp_us, payload, version)
    payload = bytes(payload)
    return b"".join((head, payload, _CRC.pack(crc16(payload, crc16(head)))))


def wire_frame(msg_type: int, seq: int, timestamp_us: int, payload: bytes, version: int = PROTOCOL_VERSION) -> bytes:
    """The frame's bytes on the wire: ``encode_frame(pack_frame(...))``, COBS and delimiter included; the same
    bytes in one compiled call (`kernels.frame_encode`) where the kernels can be had."""
    if not kernels.AVAILABLE:
        return encode_frame(pack_frame(msg_type, seq, timestamp_us, payload, version))
    return kernels.frame_encode(_pack_header(msg_type, seq, timestamp_us, payload, version) + payload)


def _pack_header(msg_type: int, seq: int, timestamp_us: int, payload: bytes, version: int) -> bytes:
    """The 18 header bytes of a frame carrying `payload`; raise `ValueError` if a field does not fit."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds MAX_PAYLOAD = {MAX_PAYLOAD}")
    try:
        return HEADER.pack(MAGIC, version, msg_type, seq % SEQ_MODULUS, timestamp_us, len(payload))
    except struct.error as exc:
        raise ValueError(f"header field out of range: {exc}") from exc


_TYPES: dict[int, MessageType] = {int(t): t for t in MessageType}


def known_type(number: int) -> int:
    """Return the `MessageType` member for `number`, or `number` itself if unknown."""
    return _TYPES.get(number, number)


def unpack_frame(frame: bytes, versions: frozenset[int] = SUPPORTED_VERSIONS) -> tuple[Header, bytes]:
    """Check a decoded frame and split it into its `Header` and payload bytes.

    Raises `FramingError` (too short or too long), `CrcError`, `BadMagicError`, `UnsupportedVersionError`
    or `BadLengthError`; the last two carry the frame's `seq` and `msg_type`.
    """
    if not MIN_FRAME_SIZE <= len(frame) <= MAX_FRAME_SIZE:
        raise FramingError(f"frame of {len(frame)} bytes, expected {MIN_FRAME_SIZE}..{MAX_FRAME_SIZE}")
    (received,) = _CRC.unpack_from(frame, len(frame) - CRC_SIZE)
    expected = crc16(memoryview(frame)[: len(frame) - CRC_SIZE])
    if expected != received:
        raise CrcError(expected, received)
    magic, version, number, seq, timestamp_us, payload_len = HEADER.unpack_from(frame)
    if magic != MAGIC:
        raise BadMagicError(f"magic 0x{magic:04X}, expected 0x{MAGIC:04X}", seq, number)
    if version not in versions:
        raise UnsupportedVersionError(f"protocol version {version} not in {sorted(versions)}", seq, number)
    actual = len(frame) - MIN_FRAME_SIZE
    if payload_len != actual:
        raise BadLengthError(f"payload_len {payload_len}, frame holds {actual} bytes", seq, number)
    header = Header(version, known_type(number), seq, timestamp_us, payload_len)
    return header, bytes(frame[HEADER_SIZE : HEADER_SIZE + payload_len])


def seq_gap(previous: int, current: int) -> int:
    """Frames lost between `previous` and `current` (wrap-aware): 0 if consecutive, < 0 if not newer.

    The distance d = (current - previous - 1) mod 2**32 counts missing frames when d < 2**31; larger
    values mean `current` is a duplicate, reordered or from a restarted sender and are returned as
    negative numbers (d - 2**32).
    """
    d = (current - previous - 1) % SEQ_MODULUS
    return d if d < SEQ_MODULUS // 2 else d - SEQ_MODULUS
