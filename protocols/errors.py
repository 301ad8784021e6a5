"""Errors of the eyehil native protocol: the exception tree and the ERROR message's code table.

Every exception a codec raises on bad input derives from `ProtocolError` (itself a `ValueError`)::

    ProtocolError                     anything the wire can get wrong
     ├── FramingError                 not a frame: COBS invalid, oversized, shorter than header + CRC
     │    └── CobsDecodeError         the COBS code bytes do not describe the input (cobs.decode)
     ├── CrcError                     CRC-16 mismatch: nothing in the frame can be trusted
     ├── BadMagicError                CRC fine, magic is not b"EH": another protocol on the link
     ├── UnsupportedVersionError      -> ERROR UNSUPPORTED_VERSION
     ├── UnknownMessageTypeError      -> ERROR UNKNOWN_MESSAGE_TYPE
     └── MalformedPayloadError        -> ERROR MALFORMED_PAYLOAD (layout wrong for the type)
          └── BadLengthError          the header's payload length disagrees with the frame

Each exception carries `seq` and `msg_type` (None where the frame could not be trusted that far) and a
class attribute `error_code`: the `ErrorCode` a device answers with, or None when the device must stay
silent (framing, CRC and magic errors are only counted: the sequence number cannot be trusted).
`eyehil.protocols.framing.FrameDecoder.feed` never raises: it reports faults as events.
Encoders raise plain `ValueError` for values that do not fit the wire (a 70-byte string, a negative
timestamp): that is a bug in the caller, not an event on the link.
"""

from __future__ import annotations

from enum import IntEnum


class ErrorCode(IntEnum):
    """Codes of the ERROR message (uint8). 0x80-0xFF are reserved for vendor extensions."""

    UNSUPPORTED_VERSION = 0x01
    UNKNOWN_MESSAGE_TYPE = 0x02
    MALFORMED_PAYLOAD = 0x03
    INVALID_ARGUMENT = 0x04
    BUSY = 0x05
    UNSUPPORTED = 0x06
    INTERNAL = 0x07


class ProtocolError(ValueError):
    """Base of every decoding error; `seq`/`msg_type` are those of the offending frame when known."""

    error_code: ErrorCode | None = None

    def __init__(self, message: str, seq: int | None = None, msg_type: int | None = None) -> None:
        super().__init__(message)
        self.seq = seq
        self.msg_type = msg_type


class FramingError(ProtocolError):
    """The bytes between two delimiters are not a frame (COBS invalid, oversized, too short)."""


class CobsDecodeError(FramingError):
    """COBS decoding failed: a code byte points past the end, or a zero byte is inside a frame."""


class CrcError(ProtocolError):
    """The CRC-16 trailer does not match the frame's contents."""

    def __init__(self, expected: int, received: int) -> None:
        super().__init__(f"CRC mismatch: computed 0x{expected:04X}, frame carries 0x{received:04X}")
        self.expected = expected
        self.received = received


class BadMagicError(ProtocolError):
    """The frame passed its CRC but does not start with the eyehil magic."""


class UnsupportedVersionError(ProtocolError):
    """The header's protocol version is not one the receiver speaks."""

    error_code = ErrorCode.UNSUPPORTED_VERSION


class UnknownMessageTypeError(ProtocolError):
    """The message type is unknown, or not one this side of the link accepts."""

    error_code = ErrorCode.UNKNOWN_MESSAGE_TYPE


class MalformedPayloadError(ProtocolError):
    """The payload does not have the layout its message type prescribes."""

    error_code = ErrorCode.MALFORMED_PAYLOAD


class BadLengthError(MalformedPayloadError):
    """The header's payload length field disagrees with the number of bytes in the frame."""
