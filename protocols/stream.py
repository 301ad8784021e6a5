"""A byte stream in, native messages out: `NativeReceiver` joins framing, decoding, counters and gaps.

Both ends of a link use it. ``feed(bytes)`` never raises; it returns, in stream order, `Received`
(header, message, frames lost just before it) and `Rejected` (the fault, and for a device the
ERROR it should send back). Sequence gaps are counted by `SequenceTracker` over every frame whose
CRC and magic were good, so a refused command still counts as received in sequence.
Still pure: no I/O, no clock, no threads.
"""

from __future__ import annotations

from dataclasses import dataclass

from eyehil.protocols.errors import (
    BadMagicError,
    CrcError,
    FramingError,
    MalformedPayloadError,
    ProtocolError,
    UnknownMessageTypeError,
    UnsupportedVersionError,
)
from eyehil.protocols.framing import MAX_FRAME_SIZE, FaultKind, FrameDecoder, FramingFault
from eyehil.protocols.header import SUPPORTED_VERSIONS, Header, MessageType, seq_gap
from eyehil.protocols.native import Message, decode, error_reply_for
from eyehil.protocols.replies import ErrorReply


@dataclass(frozen=True, slots=True)
class Received:
    """A decoded message; `lost_before` frames of the sender's sequence are missing just before it."""

    header: Header
    message: Message
    lost_before: int = 0


@dataclass(frozen=True, slots=True)
class Rejected:
    """A fault: a framing event or a decoding error, and the ERROR a device answers with (or None)."""

    error: ProtocolError | FramingFault
    reply: ErrorReply | None = None


@dataclass(slots=True)
class LinkCounters:
    """Receive-side counters, named like the STATUS fields they feed."""

    rx_frames: int = 0
    crc_errors: int = 0
    framing_errors: int = 0
    oversized_frames: int = 0
    unknown_messages: int = 0
    version_errors: int = 0
    malformed_messages: int = 0
    lost_frames: int = 0
    out_of_order: int = 0


class SequenceTracker:
    """Detects gaps in one direction's sequence numbers; the first frame seen is the baseline."""

    def __init__(self) -> None:
        """Start without a baseline."""
        self.last: int | None = None

    def update(self, seq: int) -> int:
        """Record `seq`; return frames missing before it (0), or -1 for a duplicate/old/restarted one."""
        gap = 0 if self.last is None else seq_gap(self.last, seq)
        self.last = seq
        return gap if gap >= 0 else -1


_ERROR_COUNTERS: tuple[tuple[type[ProtocolError], str], ...] = (
    (CrcError, "crc_errors"),
    (BadMagicError, "framing_errors"),
    (FramingError, "framing_errors"),
    (UnsupportedVersionError, "version_errors"),
    (UnknownMessageTypeError, "unknown_messages"),
    (MalformedPayloadError, "malformed_messages"),
)


class NativeReceiver:
    """Incremental decoder of native frames from a byte stream, with counters and gap detection."""

    def __init__(
        self,
        accept: frozenset[MessageType] | None = None,
        versions: frozenset[int] = SUPPORTED_VERSIONS,
        max_frame: int = MAX_FRAME_SIZE,
    ) -> None:
        """`accept`: message types this side takes (a device passes `native.HOST_TYPES`); None = all."""
        self.accept = accept
        self.versions = versions
        self.framer = FrameDecoder(max_frame)
        self.sequence = SequenceTracker()
        self.counters = LinkCounters()

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received | Rejected]:
        """Consume bytes; return the messages and faults they completed, in stream order."""
        return [self._event(item) for item in self.framer.feed(data)]

    def _event(self, item: bytes | FramingFault) -> Received | Rejected:
        """Turn one framing event into a `Received` or a `Rejected`, counting it."""
        if isinstance(item, FramingFault):
            name = "oversized_frames" if item.kind is FaultKind.OVERSIZED else "framing_errors"
            setattr(self.counters, name, getattr(self.counters, name) + 1)
            return Rejected(item)
        try:
            header, message = decode(item, self.accept, self.versions)
        except ProtocolError as exc:
            return self._rejected(exc)
        self.counters.rx_frames += 1
        return Received(header, message, self._track(header.seq))

    def _rejected(self, exc: ProtocolError) -> Rejected:
        """Count a decoding error; frames with a trusted seq still advance the sequence."""
        name = next((n for cls, n in _ERROR_COUNTERS if isinstance(exc, cls)), "framing_errors")
        setattr(self.counters, name, getattr(self.counters, name) + 1)
        if exc.error_code is not None and exc.seq is not None:
            self._track(exc.seq)
        return Rejected(exc, error_reply_for(exc))

    def _track(self, seq: int) -> int:
        """Update the sequence tracker and the lost/out-of-order counters; return frames lost."""
        gap = self.sequence.update(seq)
        if gap < 0:
            self.counters.out_of_order += 1
            return 0
        self.counters.lost_frames += gap
        return gap
