"""Frames on a byte stream: COBS encoding with a 0x00 delimiter, and an incremental decoder.

Sender: ``encode_frame(frame)`` = ``cobs.encode(frame) + b"\\x00"``. A sender may emit extra 0x00 bytes at
any time (for example one before its first frame, to terminate whatever garbage preceded it).

Receiver: `FrameDecoder` accumulates bytes up to each 0x00 and COBS-decodes them. It never raises:
whatever arrives, ``feed`` returns a list of events, each either the decoded frame (``bytes``) or a
`FramingFault`, and resynchronises at the next 0x00. Empty frames (two 0x00 in a row) are ignored
silently. A frame whose encoding grows beyond ``max_encoded_size(max_frame)`` is dropped as soon as it
does, reported once as an ``oversized`` fault, and the bytes up to the next 0x00 are discarded without
being buffered, so memory stays bounded whatever a broken sender emits.

This layer knows nothing of headers or CRCs: `eyehil.protocols.native.decode` checks those.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from eyehil.protocols import cobs
from eyehil.protocols.errors import CobsDecodeError, FramingError

DELIMITER = b"\x00"
MAX_FRAME_SIZE = 4116  # decoded bytes: 18-byte header + 4096-byte payload + 2-byte CRC
MAX_ENCODED_SIZE = cobs.max_encoded_size(MAX_FRAME_SIZE)  # 4133 bytes between two delimiters


class FaultKind(StrEnum):
    """Why bytes between two delimiters were not delivered as a frame."""

    COBS = "cobs"
    OVERSIZED = "oversized"


@dataclass(frozen=True, slots=True)
class FramingFault:
    """A framing error event: its kind, a human-readable detail and how many bytes it discarded."""

    kind: FaultKind
    detail: str
    discarded: int


FrameEvent = bytes | FramingFault


def encode_frame(frame: bytes | bytearray | memoryview, max_frame: int = MAX_FRAME_SIZE) -> bytes:
    """COBS-encode one frame and append the 0x00 delimiter; raise `FramingError` if it is too large."""
    if len(frame) > max_frame:
        raise FramingError(f"frame of {len(frame)} bytes exceeds the maximum of {max_frame}")
    return cobs.encode(frame) + DELIMITER


class FrameDecoder:
    """Incremental, never-raising COBS frame decoder with counters.

    Counters: ``frames`` (delivered), ``cobs_errors``, ``oversized``, ``bytes_discarded`` (bytes of
    faulty frames, including those skipped after an oversized frame).
    """

    def __init__(self, max_frame: int = MAX_FRAME_SIZE) -> None:
        """Create a decoder delivering frames of at most `max_frame` decoded bytes."""
        self.max_frame = max_frame
        self.max_encoded = cobs.max_encoded_size(max_frame)
        self._buf = bytearray()
        self._skipping = False
        self.frames = 0
        self.cobs_errors = 0
        self.oversized = 0
        self.bytes_discarded = 0

    @property
    def pending(self) -> int:
        """Bytes buffered for the frame in progress."""
        return len(self._buf)

    @property
    def between_frames(self) -> bool:
        """No frame is in progress (nothing buffered, not skipping an oversized one): the next byte starts one."""
        return not self._buf and not self._skipping

    def hand_over(self, data: bytes, first: int) -> bytes | None:
        """The frame in progress completed by `data`, whose first delimiter is at `first`: the bytes buffered for it
        and ``data[: first + 1]``, the buffer emptied (decoding what is returned is what `feed` would do with that
        part); or None (nothing changed) if it is being skipped or would grow past `max_encoded`, which `feed`
        reports."""
        if self._skipping or len(self._buf) + first > self.max_encoded:
            return None
        joined = bytes(self._buf) + data[: first + 1]
        self._buf.clear()
        return joined

    def reset(self) -> None:
        """Forget the frame in progress (counters are kept)."""
        self._buf.clear()
        self._skipping = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[FrameEvent]:
        """Consume `data`; return the frames completed and the faults met, in stream order."""
        view = bytes(data)
        events: list[FrameEvent] = []
        start = 0
        while (zero := view.find(0, start)) >= 0:
            if self._buf or self._skipping:
                self._accumulate(view[start:zero], events)
                self._finish(events)
            elif zero > start:  # a whole frame inside `data`: decoded without passing through the buffer
                self._whole(view[start:zero], events)
            start = zero + 1
        self._accumulate(view[start:], events)
        return events

    def _accumulate(self, chunk: bytes, events: list[FrameEvent]) -> None:
        """Add delimiter-free bytes to the frame in progress, or skip them after an overflow."""
        if self._skipping:
            self.bytes_discarded += len(chunk)
            return
        self._buf += chunk
        if len(self._buf) > self.max_encoded:
            self._fault(FaultKind.OVERSIZED, f"more than {self.max_encoded} encoded bytes", events)
            self._skipping = True

    def _finish(self, events: list[FrameEvent]) -> None:
        """Handle a delimiter: deliver, report or ignore the bytes gathered since the previous one."""
        if self._skipping:
            self._skipping = False
            return
        if not self._buf:
            return
        self._decode(bytes(self._buf), events)
        self._buf.clear()

    def _whole(self, encoded: bytes, events: list[FrameEvent]) -> None:
        """Handle the non-empty bytes between two delimiters of one `feed`, as `_accumulate` then `_finish` would."""
        if len(encoded) > self.max_encoded:
            self._report(FaultKind.OVERSIZED, f"more than {self.max_encoded} encoded bytes", len(encoded), events)
        else:
            self._decode(encoded, events)

    def _decode(self, encoded: bytes, events: list[FrameEvent]) -> None:
        """Deliver the frame `encoded` holds, or report why not."""
        try:
            frame = cobs.decode(encoded)
        except CobsDecodeError as exc:
            self._report(FaultKind.COBS, str(exc), len(encoded), events)
            return
        if len(frame) > self.max_frame:
            self._report(FaultKind.OVERSIZED, f"{len(frame)} decoded bytes > {self.max_frame}", len(encoded), events)
            return
        self.frames += 1
        events.append(frame)

    def _fault(self, kind: FaultKind, detail: str, events: list[FrameEvent]) -> None:
        """Count and report a fault, dropping the buffered bytes."""
        self._report(kind, detail, len(self._buf), events)
        self._buf.clear()

    def _report(self, kind: FaultKind, detail: str, discarded: int, events: list[FrameEvent]) -> None:
        """Count and report a fault that discarded `discarded` bytes."""
        if kind is FaultKind.COBS:
            self.cobs_errors += 1
        else:
            self.oversized += 1
        self.bytes_discarded += discarded
        events.append(FramingFault(kind, detail, discarded))
