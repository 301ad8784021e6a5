"""Replies of the eyehil native protocol (device -> host): PONG, ACK, STATUS, DEVICE_INFO, ERROR.

Same conventions as `eyehil.protocols.messages`: frozen dataclasses with ``TYPE``, ``to_payload()`` and
``from_payload()``; the wire layout is given in each class docstring and in docs/protocol.md.
"""

from __future__ import annotations

import struct
from contextlib import suppress
from dataclasses import dataclass
from typing import ClassVar, Self

from eyehil.protocols.enums import Capability, DeviceState
from eyehil.protocols.errors import ErrorCode, MalformedPayloadError
from eyehil.protocols.header import MessageType
from eyehil.protocols.messages import Fixed, check_length, field_values, pack_text, unpack_text


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
class Ack(Fixed):
    """device -> host: a command was accepted. ``<IB``: its sequence number and message type."""

    TYPE = MessageType.ACK
    STRUCT = struct.Struct("<IB")
    acked_seq: int
    acked_type: int

    def __post_init__(self) -> None:
        """Use the `MessageType` member when the type is known."""
        with suppress(ValueError):
            object.__setattr__(self, "acked_type", MessageType(self.acked_type))


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
        with suppress(ValueError):
            object.__setattr__(self, "code", ErrorCode(self.code))

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
