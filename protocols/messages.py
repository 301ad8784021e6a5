"""Commands of the eyehil native protocol (host -> device), and the helpers every message class uses.

Every message class has ``TYPE`` (its `MessageType`), ``to_payload() -> bytes`` and
``from_payload(bytes)`` (raises `MalformedPayloadError`). Fixed-layout messages are one little-endian
struct of their fields in declaration order (`Fixed`); the struct format is given next to each class.
Replies are in `eyehil.protocols.replies`, streamed samples (FEATURES, FRAME_CHUNK) in `eyehil.protocols.samples`.
Wire layouts: docs/protocol.md.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import ClassVar, Self

from eyehil.protocols.enums import EyeSelect, StimulusFlags, StreamSelect
from eyehil.protocols.errors import MalformedPayloadError
from eyehil.protocols.header import MessageType

MAX_TEXT = 64  # bytes of UTF-8 in a string field


def check_length(payload: bytes, expected: int, what: str) -> None:
    """Raise `MalformedPayloadError` unless `payload` holds exactly `expected` bytes."""
    if len(payload) != expected:
        raise MalformedPayloadError(f"{what} payload of {len(payload)} bytes, expected {expected}")


def pack_text(text: str) -> bytes:
    """A string field: uint8 byte count, then that many bytes of UTF-8 (at most MAX_TEXT)."""
    raw = text.encode("utf-8")
    if len(raw) > MAX_TEXT:
        raise ValueError(f"string of {len(raw)} UTF-8 bytes exceeds {MAX_TEXT}: {text[:20]!r}...")
    return bytes([len(raw)]) + raw


def unpack_text(payload: bytes, offset: int) -> tuple[str, int]:
    """Read a string field at `offset`; return it and the offset after it."""
    if offset >= len(payload):
        raise MalformedPayloadError(f"string length byte missing at offset {offset}")
    end = offset + 1 + payload[offset]
    if payload[offset] > MAX_TEXT or end > len(payload):
        raise MalformedPayloadError(f"string of {payload[offset]} bytes at offset {offset} does not fit")
    try:
        return payload[offset + 1 : end].decode("utf-8"), end
    except UnicodeDecodeError as exc:
        raise MalformedPayloadError(f"string at offset {offset} is not UTF-8") from exc


def field_values(message: object) -> tuple:
    """The dataclass fields of `message` in declaration order (shallow, unlike `dataclasses.astuple`)."""
    return tuple(getattr(message, f.name) for f in fields(message))  # type: ignore[arg-type]


def truncate_utf8(text: str, limit: int = MAX_TEXT) -> str:
    """`text` cut to at most `limit` UTF-8 bytes without splitting a character."""
    return text.encode("utf-8")[:limit].decode("utf-8", errors="ignore")


class Fixed:
    """Mixin: the payload is ``STRUCT`` packed with the dataclass fields in declaration order."""

    __slots__ = ()
    TYPE: ClassVar[MessageType]
    STRUCT: ClassVar[struct.Struct]

    def to_payload(self) -> bytes:
        """Encode the fields; raise `ValueError` if one does not fit its wire type."""
        try:
            return self.STRUCT.pack(*field_values(self))
        except struct.error as exc:
            raise ValueError(f"{type(self).__name__}: {exc}") from exc

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode a payload of exactly ``STRUCT.size`` bytes."""
        check_length(payload, cls.STRUCT.size, cls.TYPE.name)
        return cls(*cls.STRUCT.unpack(payload))


@dataclass(frozen=True, slots=True)
class Ping(Fixed):
    """host -> device: time-sync probe; the device answers PONG. Payload ``<I``: nonce."""

    TYPE = MessageType.PING
    STRUCT = struct.Struct("<I")
    nonce: int = 0


@dataclass(frozen=True, slots=True)
class GetInfo(Fixed):
    """host -> device: ask for DEVICE_INFO. Empty payload; accepted in protocol version 1 by every device."""

    TYPE = MessageType.GET_INFO
    STRUCT = struct.Struct("<")


@dataclass(frozen=True, slots=True)
class Start(Fixed):
    """host -> device: start streaming with the current configuration. Empty payload."""

    TYPE = MessageType.START
    STRUCT = struct.Struct("<")


@dataclass(frozen=True, slots=True)
class Stop(Fixed):
    """host -> device: stop streaming; nothing streamed follows its ACK. Empty payload."""

    TYPE = MessageType.STOP
    STRUCT = struct.Struct("<")


@dataclass(frozen=True, slots=True)
class GetStatus(Fixed):
    """host -> device: ask for STATUS. Empty payload."""

    TYPE = MessageType.GET_STATUS
    STRUCT = struct.Struct("<")


@dataclass(frozen=True, slots=True)
class Configure(Fixed):
    """host -> device: configuration for the next START. ``<BHBBHHHH``: LEDs (1 or 2), rate (Hz,
    30..2000), eyes (EyeSelect), stream (StreamSelect), region of interest x, y, w, h (px, sensor
    coordinates; w = h = 0 means the full sensor)."""

    TYPE = MessageType.CONFIGURE
    STRUCT = struct.Struct("<BHBBHHHH")
    leds: int
    rate_hz: int
    eyes: EyeSelect = EyeSelect.BOTH
    stream: StreamSelect = StreamSelect.FEATURES
    roi_x: int = 0
    roi_y: int = 0
    roi_w: int = 0
    roi_h: int = 0

    def __post_init__(self) -> None:
        """Coerce the bit sets to their flag types."""
        object.__setattr__(self, "eyes", EyeSelect(self.eyes))
        object.__setattr__(self, "stream", StreamSelect(self.stream))


@dataclass(frozen=True, slots=True)
class Stimulus(Fixed):
    """host -> emulator only: where the simulated subject's target is. ``<IffB``: target id, x, y (mm,
    screen plane, origin at the top-left corner of the active area, x right, y down), StimulusFlags."""

    TYPE = MessageType.STIMULUS
    STRUCT = struct.Struct("<IffB")
    target_id: int
    x_mm: float
    y_mm: float
    flags: StimulusFlags = StimulusFlags.VISIBLE

    def __post_init__(self) -> None:
        """Coerce the flags."""
        object.__setattr__(self, "flags", StimulusFlags(self.flags))
