"""Commands and replies of the eyehil native protocol: one frozen dataclass per message type.

Every message class has ``TYPE`` (its `MessageType`), ``to_payload() -> bytes`` and
``from_payload(bytes)`` (raises `MalformedPayloadError`). Fixed-layout messages are one little-endian
struct of their fields in declaration order (`Fixed`); the struct format is given next to each class.
Streamed samples (FEATURES, FRAME_CHUNK) live in `protocols.samples`. See docs/protocol.md.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import ClassVar, Self

from protocols.enums import Capability, DeviceState, EyeSelect, StimulusFlags, StreamSelect
from protocols.errors import ErrorCode, MalformedPayloadError
from protocols.header import MessageType

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
class Pong(Fixed):
    """device -> host: answer to PING. ``<IQQ``: nonce, the PING's header timestamp (host clock, us),
    device clock (us) when the PING was received. The PONG's header timestamp is its send time."""

    TYPE = MessageType.PONG
    STRUCT = struct.Struct("<IQQ")
    nonce: int
    ping_timestamp_us: int
    receive_time_us: int


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


@dataclass(frozen=True, slots=True)
class Ack(Fixed):
    """device -> host: a command was accepted. ``<IB``: its sequence number and message type."""

    TYPE = MessageType.ACK
    STRUCT = struct.Struct("<IB")
    acked_seq: int
    acked_type: int


@dataclass(frozen=True, slots=True)
class Status(Fixed):
    """device -> host: answer to GET_STATUS. ``<B13I``: DeviceState, then uint32 counters since power-up
    (wrapping), in this order."""

    TYPE = MessageType.STATUS
    STRUCT = struct.Struct("<B13I")
    state: DeviceState = DeviceState.IDLE
    rx_frames: int = 0  # valid frames received
    tx_frames: int = 0  # frames sent
    samples_sent: int = 0  # FEATURES messages sent
    frames_sent: int = 0  # camera images sent completely
    samples_dropped: int = 0  # samples not sent (link too slow, buffer full)
    frames_dropped: int = 0  # camera images not sent or sent partly
    crc_errors: int = 0
    framing_errors: int = 0  # COBS errors, frames too short, bad magic
    oversized_frames: int = 0
    unknown_messages: int = 0  # refused with UNKNOWN_MESSAGE_TYPE
    version_errors: int = 0  # refused with UNSUPPORTED_VERSION
    malformed_messages: int = 0  # refused with MALFORMED_PAYLOAD
    commands_refused: int = 0  # every ERROR sent

    def __post_init__(self) -> None:
        """Coerce the state (an unknown state is malformed)."""
        object.__setattr__(self, "state", DeviceState(self.state))


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """device -> host: answer to GET_INFO. ``<BBHHHHHBHH`` then two strings (see docs/protocol.md)."""

    TYPE: ClassVar[MessageType] = MessageType.DEVICE_INFO
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BBHHHHHBHH")
    protocol_min: int
    protocol_max: int
    camera_width: int  # px
    camera_height: int  # px
    min_rate_hz: int
    max_rate_hz: int
    sample_rate_hz: int  # the rate START uses now (default until CONFIGURE)
    led_count: int
    capabilities: Capability
    max_payload: int  # largest payload the device sends or accepts, <= 4096
    model: str
    firmware_version: str

    def __post_init__(self) -> None:
        """Coerce the capability bits."""
        object.__setattr__(self, "capabilities", Capability(self.capabilities))

    def to_payload(self) -> bytes:
        """Encode the fixed part then the two strings."""
        try:
            fixed = self.STRUCT.pack(*field_values(self)[:-2])
        except struct.error as exc:
            raise ValueError(f"DeviceInfo: {exc}") from exc
        return fixed + pack_text(self.model) + pack_text(self.firmware_version)

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode; the strings must end exactly at the end of the payload."""
        if len(payload) < cls.STRUCT.size:
            raise MalformedPayloadError(f"DEVICE_INFO payload of {len(payload)} bytes is too short")
        model, offset = unpack_text(payload, cls.STRUCT.size)
        firmware, offset = unpack_text(payload, offset)
        check_length(payload, offset, "DEVICE_INFO")
        return cls(*cls.STRUCT.unpack_from(payload), model, firmware)


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """device -> host: a command was refused. ``<BIB`` code (ErrorCode), offending seq, offending type,
    then a string (short UTF-8 explanation, at most 64 bytes)."""

    TYPE: ClassVar[MessageType] = MessageType.ERROR
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<BIB")
    code: int
    offending_seq: int
    offending_type: int
    text: str = ""

    def __post_init__(self) -> None:
        """Use the `ErrorCode` member when the code is known (vendor codes stay ints)."""
        try:
            object.__setattr__(self, "code", ErrorCode(self.code))
        except ValueError:
            pass

    def to_payload(self) -> bytes:
        """Encode the fixed part then the text."""
        try:
            fixed = self.STRUCT.pack(self.code, self.offending_seq, self.offending_type)
        except struct.error as exc:
            raise ValueError(f"ErrorReply: {exc}") from exc
        return fixed + pack_text(self.text)

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode; the text must end exactly at the end of the payload."""
        if len(payload) < cls.STRUCT.size:
            raise MalformedPayloadError(f"ERROR payload of {len(payload)} bytes is too short")
        text, offset = unpack_text(payload, cls.STRUCT.size)
        check_length(payload, offset, "ERROR")
        return cls(*cls.STRUCT.unpack_from(payload), text)
