"""The host end of a native-protocol link: sequence-numbered sends, and a receive path that never hangs.

`Wire` owns one SerialLike (`eyehil.drivers.links`) and a `protocols.NativeReceiver`. `pump(wait_s)` reads
whatever arrives within `wait_s` seconds (waiting with select() on the link's descriptor when it has one, else with
the link's own read timeout; a link that can be read without waiting, `read_now` or a pyserial posix port's
descriptor, is drained up to `DRAIN` bytes between two selects, since a pseudo-terminal gives at most 4 kB a read
and each decoding call has a cost of its own), decodes it, and sorts it: FEATURES become `Sample`s in `samples`,
FRAME_CHUNKs are reassembled (`eyehil.protocols.images.ImageAssembler`; those that follow one another arrive as one
`protocols.ChunkRun`) into `ReceivedImage`s in `images`, every other message goes to `replies` with its arrival
time. Faults are counted, never raised (`HostStats`); only a failing link raises (`LinkError`). A FEATURES or
FRAME_CHUNK whose seq is not newer than the last one (a duplicate or a late frame, already counted lost when its
successor came) never reaches the application: it is dropped and counted (`duplicates_dropped`). Reassembly
allocates at most `max_image_bytes` per image (`eyehil.protocols.images.ImageAssembler`). Host times are microseconds of
``time.monotonic_ns()``.
"""

from __future__ import annotations

import os
import select
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields, replace

from eyehil.drivers.errors import LinkError
from eyehil.protocols.header import SEQ_MODULUS, Header, seq_gap
from eyehil.protocols.images import Image, ImageAssembler
from eyehil.protocols.native import DEVICE_TYPES, Message, encode
from eyehil.protocols.replies import ErrorReply
from eyehil.protocols.samples import EyeFeatures, Features, FrameChunk
from eyehil.protocols.stream import ChunkRun, NativeReceiver, Received

CHUNK = 65536  # bytes asked of the link in one read
DRAIN = 4 * CHUNK  # bytes gathered from a link that can be read without waiting before they are decoded (`_drain`)
MAX_BUFFERED_SAMPLES = 200_000
MAX_BUFFERED_IMAGES = 256


def host_now_us() -> int:
    """The host's monotonic clock, microseconds."""
    return time.monotonic_ns() // 1000


@dataclass(frozen=True, slots=True)
class Sample:
    """One FEATURES message as received: device time (mid-exposure) and host arrival time, us.

    `lost_before`: link frames lost just before it (sequence gap); `skipped_before`: camera exposures
    missing just before it (frame_id gap: lost on the link, never sent by the device, or discarded unread when
    the host's buffer was full, whose gaps the next sample inherits).
    """

    seq: int
    frame_id: int
    device_us: int
    host_us: int
    eyes: tuple[EyeFeatures, ...]
    lost_before: int = 0
    skipped_before: int = 0

    def eye(self, which: int) -> EyeFeatures | None:
        """The record of eye `which` (protocols.Eye), or None if the stream does not carry it."""
        return next((e for e in self.eyes if e.eye == which), None)


@dataclass(frozen=True, slots=True)
class ReceivedImage:
    """A reassembled camera image, the exposure's device time (mid-exposure, us), when its last chunk arrived
    (host us) and that chunk's sequence number."""

    image: Image
    device_us: int
    host_us: int
    seq: int


@dataclass(frozen=True, slots=True)
class Reply:
    """A non-sample message and when it arrived (host us)."""

    received: Received
    host_us: int

    @property
    def message(self) -> Message:
        return self.received.message


@dataclass
class HostStats:
    """What the host counted on this link (receive side, plus its own command bookkeeping)."""

    rx_frames: int = 0  # frames decoded
    samples: int = 0  # FEATURES received
    lost_frames: int = 0  # sequence gaps: frames the device sent that never arrived intact
    out_of_order: int = 0  # duplicate, late or restarted sequence numbers
    skipped_exposures: int = 0  # frame_id gaps within a stream
    crc_errors: int = 0
    framing_errors: int = 0
    oversized_frames: int = 0
    unknown_messages: int = 0
    version_errors: int = 0
    malformed_messages: int = 0
    errors_received: int = 0  # ERROR replies
    retries: int = 0  # commands re-sent after a missing response
    stale_replies: int = 0  # replies that matched no outstanding command
    samples_overflowed: int = 0  # samples discarded because nobody read them
    duplicates_dropped: int = 0  # duplicated or late FEATURES/FRAME_CHUNKs not delivered
    mismatched_replies: int = 0  # replies naming our command's seq with the wrong type (or type with wrong seq)
    chunks: int = 0  # FRAME_CHUNKs received
    images: int = 0  # images reassembled whole
    images_incomplete: int = 0  # images abandoned with chunks missing, or with inconsistent chunks
    images_overflowed: int = 0  # images discarded because nobody read them
    images_refused: int = 0  # FRAME_CHUNKs claiming an image larger than the limit, or inconsistent chunking

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _reader(link) -> Callable[[int], bytes] | None:
    """A read of `link` that never waits: its `read_now`, or a pyserial posix port's descriptor read directly."""
    read_now = getattr(link, "read_now", None)
    if read_now is not None:
        return read_now
    try:
        from serial.serialposix import Serial as PosixSerial
    except ImportError:  # not a posix system
        return None
    if type(link) is not PosixSerial:  # a subclass may read differently (and a fault or spy link wraps one)
        return None

    def read_fd(size: int) -> bytes:  # pyserial sets VMIN = VTIME = 0: b"" when nothing is there
        try:
            return os.read(link.fd, size)
        except BlockingIOError:
            return b""

    return read_fd


class Wire:
    """See the module docstring."""

    def __init__(self, link, seq0: int = 1) -> None:
        """Use `link` (SerialLike); commands are numbered from `seq0`."""
        self.link = link
        self.receiver = NativeReceiver(accept=DEVICE_TYPES, chunk_runs=True)
        self.samples: deque[Sample] = deque()
        self.replies: deque[Reply] = deque()
        self.images: deque[ReceivedImage] = deque()
        self.assembler = ImageAssembler()
        self.stats = HostStats()
        self.seq = seq0 % SEQ_MODULUS
        self._last_frame_id: int | None = None
        self._select = hasattr(link, "fileno")
        if self._select:
            link.timeout = 0
        self._read_now = _reader(link) if self._select else None

    def send(self, message: Message) -> tuple[int, int]:
        """Encode and write `message`; return its (seq, host timestamp us)."""
        seq, now = self.seq, host_now_us()
        self.seq = (seq + 1) % SEQ_MODULUS
        self.write(encode(message, seq, now))
        return seq, now

    def write(self, data: bytes) -> None:
        """Raw bytes to the device."""
        try:
            self.link.write(data)
        except OSError as exc:
            raise LinkError(f"write failed: {exc}") from exc

    def new_stream(self) -> None:
        """A stream starts: frame ids get a new baseline."""
        self._last_frame_id = None

    def _read(self, wait_s: float) -> bytes:
        """Bytes arriving within `wait_s` (b"" if none)."""
        link = self.link
        try:
            if self._read_now is not None:
                data = self._drain()
                if not data and wait_s > 0 and select.select([link.fileno()], [], [], wait_s)[0]:
                    data = self._drain()
                    if not data:
                        raise LinkError("the link reported data and gave none: the device went away")
                return data
            if self._select:
                data = link.read(CHUNK)
                if not data and wait_s > 0 and select.select([link.fileno()], [], [], wait_s)[0]:
                    data = link.read(CHUNK)
                return data
            link.timeout = 0
            data = link.read(CHUNK)
            if not data and wait_s > 0:
                link.timeout = wait_s
                data = link.read(1)
                link.timeout = 0
                if data:
                    try:
                        data += link.read(CHUNK)
                    except OSError:  # the byte that arrived is not lost: decode it, then report the failure
                        self._feed(data)
                        raise
            return data
        except OSError as exc:
            raise LinkError(f"read failed: {exc}") from exc

    def _drain(self) -> bytes:
        """What the link holds now, up to `DRAIN` bytes, read without waiting, `CHUNK` at most a read (if a later read
        fails, what came before it is decoded first)."""
        data = self._read_now(CHUNK)
        pieces, size = [data], len(data)
        while data and size < DRAIN:
            try:
                data = self._read_now(min(CHUNK, DRAIN - size))
            except OSError:
                self._feed(b"".join(pieces))
                raise
            pieces.append(data)
            size += len(data)
        return b"".join(pieces)

    def pump(self, wait_s: float = 0.0) -> int:
        """Read and dispatch what arrives within `wait_s` s; return the number of bytes read."""
        data = self._read(max(0.0, wait_s))
        if data:
            self._feed(data)
        return len(data)

    def _feed(self, data: bytes) -> None:
        """Decode `data` and dispatch its samples, replies and image chunks."""
        now = host_now_us()
        for event in self.receiver.feed(data):
            if type(event) is ChunkRun:
                self._run(event, now)
            elif isinstance(event, Received):
                self._dispatch(event, now)
        self._sync_counters()

    def _dispatch(self, event: Received, now: int) -> None:
        message = event.message
        if event.out_of_order and isinstance(message, Features | FrameChunk):
            self.stats.duplicates_dropped += 1
            return
        if isinstance(message, FrameChunk):
            self._chunk(message, event.header, now)
            return
        if not isinstance(message, Features):
            self.stats.errors_received += isinstance(message, ErrorReply)
            self.replies.append(Reply(event, now))
            return
        skipped = 0
        if self._last_frame_id is not None:
            skipped = max(0, seq_gap(self._last_frame_id, message.frame_id))
        self._last_frame_id = message.frame_id
        self.stats.skipped_exposures += skipped
        self.stats.samples += 1
        h = event.header
        self.samples.append(Sample(h.seq, message.frame_id, h.timestamp_us, now, message.eyes, event.lost_before,
                                   skipped))
        if len(self.samples) > MAX_BUFFERED_SAMPLES:
            self._overflow()

    def _overflow(self) -> None:
        """Discard the oldest unread sample; the next one inherits its gaps, plus its own exposure, so what the
        application reads still marks every gap (`skipped_before` equals the frame_id gap)."""
        dropped = self.samples.popleft()
        self.stats.samples_overflowed += 1
        head = self.samples[0]  # there is one: the sample just appended at least
        self.samples[0] = replace(head, lost_before=head.lost_before + dropped.lost_before,
                                  skipped_before=head.skipped_before + dropped.skipped_before + 1)

    def _chunk(self, chunk: FrameChunk, header: Header, now: int) -> None:
        """Add a chunk to its image; keep the image when it is whole."""
        self.stats.chunks += 1
        image = self.assembler.add(chunk)
        if image is not None:
            self._keep(image, header.timestamp_us, header.seq, now)
        self._sync_images()

    def _run(self, run: ChunkRun, now: int) -> None:
        """Add a run of chunks to its image, as `_chunk` each; keep the images they complete."""
        self.stats.chunks += len(run)
        for k, image in self.assembler.add_run(run.first, run.rest):
            self._keep(image, run.header.timestamp_us, run.seq(k), now)
        self._sync_images()

    def _keep(self, image: Image, device_us: int, seq: int, now: int) -> None:
        """A whole image, for the application (the oldest unread is dropped beyond `MAX_BUFFERED_IMAGES`)."""
        self.stats.images += 1
        if len(self.images) >= MAX_BUFFERED_IMAGES:
            self.images.popleft()
            self.stats.images_overflowed += 1
        self.images.append(ReceivedImage(image, device_us, now, seq))

    def _sync_images(self) -> None:
        self.stats.images_incomplete = self.assembler.incomplete + self.assembler.inconsistent
        self.stats.images_refused = self.assembler.refused

    def _sync_counters(self) -> None:
        c = self.receiver.counters
        for name in ("rx_frames", "lost_frames", "out_of_order", "crc_errors", "framing_errors", "oversized_frames",
                     "unknown_messages", "version_errors", "malformed_messages"):
            setattr(self.stats, name, getattr(c, name))

    def close(self) -> None:
        """Close the link."""
        self.link.close()
