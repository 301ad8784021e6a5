"""A byte stream in, native messages out: `NativeReceiver` joins framing, decoding, counters and gaps.

Both ends of a link use it. ``feed(bytes)`` never raises; it returns, in stream order, `Received`
(header, message, frames lost just before it) and `Rejected` (the fault, and for a device the
ERROR it should send back). Sequence gaps are counted by `SequenceTracker` over every frame whose
CRC and magic were good, so a refused command still counts as received in sequence. A frame whose seq is
not newer than the last one is flagged (`Received.out_of_order`): a duplicate or a late frame (at most
`REORDER_WINDOW` behind) leaves the baseline where it was, so that the frames after it are not counted
lost twice; one farther behind is a restarted sender and becomes the new baseline.
Still pure: no I/O, no clock, no threads. Where the compiled kernels can be had, the frames that lie whole in
one `feed` are COBS-decoded and checked in one call (`eyehil.protocols.kernels.decode_frames`) and only the
message is built in Python; a frame the kernel does not pass takes the per-frame path, which reports it, so the
events and counters are the same either way (tests/test_protocol_stream.py). A host asks for `chunk_runs`: there,
a FRAME_CHUNK that continues the one before it in such a call (the next seq, the same image, header timestamp and
geometry, inside the image) is not built as a message of its own but joins that one's `ChunkRun` as (index, offset,
bytes), a few microseconds instead of some ten; a run stands for exactly the `Received` events of its chunks
(`ChunkRun.received`, tests/test_protocol_chunk_runs.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from eyehil.protocols import kernels
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
from eyehil.protocols.header import (
    HEADER_SIZE,
    SEQ_MODULUS,
    SUPPORTED_VERSIONS,
    Header,
    MessageType,
    known_type,
    seq_gap,
)
from eyehil.protocols.native import Message, decode, decode_payload, error_reply_for
from eyehil.protocols.replies import ErrorReply
from eyehil.protocols.samples import FrameChunk


@dataclass(frozen=True, slots=True)
class Received:
    """A decoded message; `lost_before` frames of the sender's sequence are missing just before it."""

    header: Header
    message: Message
    lost_before: int = 0
    out_of_order: bool = False  # a duplicate, late or restarted seq (see the module docstring)


@dataclass(frozen=True, slots=True)
class Rejected:
    """A fault: a framing event or a decoding error, and the ERROR a device answers with (or None)."""

    error: ProtocolError | FramingFault
    reply: ErrorReply | None = None


@dataclass(slots=True)
class ChunkRun:
    """FRAME_CHUNKs of one image that came one after another (the host's bulk of traffic), as one event: `first`,
    received as any message (`header` its header, `lost_before` the frames missing before it), then the pieces of the
    chunks after it, (chunk_index, offset, pixel bytes) in `rest`. Each of those has the next seq (the k-th after
    `first` has seq + k, mod 2**32), `first`'s protocol version, header timestamp, frame id, eye, geometry and chunk
    count, and passes `FrameChunk`'s own checks (index below the count, bytes inside the image); a chunk that does
    not is not part of a run. Built in place by `NativeReceiver`, which counts and sequences every chunk of it as a
    `Received`."""

    header: Header
    first: FrameChunk
    lost_before: int
    rest: list[tuple[int, int, bytes]] = field(default_factory=list)
    _head: tuple = field(init=False, default=())  # `first`'s raw frame id, eye, format, size, roi and chunk count
    _size: int = field(init=False, default=0)  # `first`'s image size, bytes

    def __post_init__(self) -> None:
        c = self.first
        self._head = (c.frame_id, int(c.eye), int(c.pixel_format), c.width, c.height, c.roi_x, c.roi_y, c.chunk_count)
        self._size = c.image_size

    def __len__(self) -> int:
        """The chunks in the run."""
        return 1 + len(self.rest)

    def seq(self, k: int) -> int:
        """The seq of the run's `k`-th chunk (`first` 0)."""
        return (self.header.seq + k) % SEQ_MODULUS

    def received(self) -> list[Received]:
        """The run as the `Received` events its chunks stand for, one a chunk (what a receiver without `chunk_runs`
        gives)."""
        h, c = self.header, self.first
        events = [Received(h, c, self.lost_before)]
        for k, (index, offset, data) in enumerate(self.rest, 1):
            header = replace(h, seq=self.seq(k), payload_len=_CHUNK_HEAD + len(data))
            events.append(Received(header, replace(c, chunk_index=index, offset=offset, data=data)))
        return events

    def extend(self, decoded: memoryview, body: int, version: int, number: int, seq: int, timestamp: int,
               payload_len: int) -> bool:
        """Take the checked frame whose payload is ``decoded[body : body + payload_len]`` (its header fields as the
        kernel gives them, the timestamp unsigned) if it continues the run; False (nothing taken) if not."""
        h = self.header
        if (number != _FRAME_CHUNK or seq != self.seq(len(self.rest) + 1) or timestamp != h.timestamp_us
                or version != h.version or payload_len < _CHUNK_HEAD):
            return False
        frame_id, eye, fmt, width, height, roi_x, roi_y, index, count, offset = _CHUNK_STRUCT.unpack_from(decoded, body)
        end = offset + payload_len - _CHUNK_HEAD
        if ((frame_id, eye, fmt, width, height, roi_x, roi_y, count) != self._head or index >= count
                or end > self._size):
            return False
        self.rest.append((index, offset, decoded[body + _CHUNK_HEAD : body + payload_len].tobytes()))
        return True


_FRAME_CHUNK = int(MessageType.FRAME_CHUNK)
_CHUNK_STRUCT = FrameChunk.STRUCT
_CHUNK_HEAD = FrameChunk.STRUCT.size


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


REORDER_WINDOW = 4096  # frames: a seq at most this far behind the baseline is a duplicate or late frame


class SequenceTracker:
    """Detects gaps in one direction's sequence numbers; the first frame seen is the baseline."""

    def __init__(self) -> None:
        """Start without a baseline."""
        self.last: int | None = None

    def update(self, seq: int) -> int:
        """Record `seq`; return frames missing before it (0), or -1 for a duplicate/old/restarted one.

        A duplicate or late frame (at most `REORDER_WINDOW` behind) keeps the baseline; a frame farther
        behind (a restarted sender) becomes the baseline.
        """
        gap = 0 if self.last is None else seq_gap(self.last, seq)
        if gap >= 0 or gap < -REORDER_WINDOW - 1:
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
        chunk_runs: bool = False,
    ) -> None:
        """`accept`: message types this side takes (a device passes `native.HOST_TYPES`); None = all. `chunk_runs`:
        FRAME_CHUNKs that follow one another come as `ChunkRun`s where the compiled kernels check them (a host)."""
        self.accept = accept
        self.versions = versions
        self.framer = FrameDecoder(max_frame)
        self.sequence = SequenceTracker()
        self.counters = LinkCounters()
        self.chunk_runs = chunk_runs
        self._buffers = kernels.FrameBuffers() if kernels.AVAILABLE else None

    def feed(self, data: bytes | bytearray | memoryview) -> list[Received | ChunkRun | Rejected]:
        """Consume bytes; return the messages and faults they completed, in stream order."""
        view = bytes(data)
        last = view.rfind(0)
        if last < 0 or not kernels.AVAILABLE:  # no delimiter: the frame in progress only grows
            return [self._event(item) for item in self.framer.feed(view)]
        events: list[Received | ChunkRun | Rejected] = []
        start = 0
        if not self.framer.between_frames:  # the frame in progress ends at the first delimiter
            first = view.find(0)
            joined = self.framer.hand_over(view, first)
            if joined is None:
                events += [self._event(item) for item in self.framer.feed(view[: first + 1])]
            else:
                self._whole(joined, 0, len(joined), events)
            start = first + 1
        if start <= last:
            self._whole(view, start, last + 1, events)
        events += [self._event(item) for item in self.framer.feed(view[last + 1 :])]
        return events

    def _whole(self, data: bytes, start: int, end: int, events: list[Received | ChunkRun | Rejected]) -> None:
        """The frames ``data[start:end]`` holds whole (it starts between frames and ends at a delimiter), checked in
        one compiled call; a frame it does not pass, or whose version this side does not take, goes through the
        framer and `_event` as if fed alone, which report it. With `chunk_runs`, a FRAME_CHUNK that continues the
        run before it (`ChunkRun`) joins it."""
        decoded, records = kernels.decode_frames(data, self.framer.max_encoded, self.framer.max_frame, self._buffers,
                                                 start, end)
        run: ChunkRun | None = None
        for at, length, offset, _, verdict, version, number, seq, timestamp_us, payload_len in records:
            if verdict or version not in self.versions:
                run = None
                events += [self._event(item) for item in self.framer.feed(data[at : at + length + 1])]
                continue
            self.framer.frames += 1
            body, timestamp_us = offset + HEADER_SIZE, timestamp_us & 0xFFFFFFFFFFFFFFFF
            if run is not None and run.extend(decoded, body, version, number, seq, timestamp_us, payload_len):
                self.counters.rx_frames += 1
                self.sequence.last = seq  # the next in sequence: no gap, not out of order
                continue
            run = None
            header = Header(version, known_type(number), seq, timestamp_us, payload_len)
            try:
                message = decode_payload(header, decoded[body : body + payload_len].tobytes(), self.accept)
            except ProtocolError as exc:
                events.append(self._rejected(exc))
                continue
            event = self._received(header, message)
            if self.chunk_runs and type(message) is FrameChunk and not event.out_of_order:
                event = run = ChunkRun(header, message, event.lost_before)
            events.append(event)

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
        return self._received(header, message)

    def _received(self, header: Header, message: Message) -> Received:
        """Count a decoded message and place it in the sequence."""
        self.counters.rx_frames += 1
        lost = self._track(header.seq)
        return Received(header, message, max(lost, 0), lost < 0)

    def _rejected(self, exc: ProtocolError) -> Rejected:
        """Count a decoding error; frames with a trusted seq still advance the sequence."""
        name = next((n for cls, n in _ERROR_COUNTERS if isinstance(exc, cls)), "framing_errors")
        setattr(self.counters, name, getattr(self.counters, name) + 1)
        if exc.error_code is not None and exc.seq is not None:
            self._track(exc.seq)
        return Rejected(exc, error_reply_for(exc))

    def _track(self, seq: int) -> int:
        """Update the sequence tracker and the lost/out-of-order counters; return frames lost (-1: out of order)."""
        gap = self.sequence.update(seq)
        if gap < 0:
            self.counters.out_of_order += 1
            return -1
        self.counters.lost_frames += gap
        return gap
