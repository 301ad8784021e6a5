"""Camera images as FRAME_CHUNK messages: split on the device side, reassemble on the host side.

Pure helpers around `eyehil.protocols.samples.FrameChunk`. `split_image` gives an image's chunks as messages;
`ImageChunks` gives their wire bytes a run at a time, numbered as they go (the device's path: one compiled call
a run, `eyehil.protocols.kernels.chunk_frames`, the same bytes as encoding each `split_image` chunk with
`eyehil.protocols.native.encode`). The device sends the chunks of one image in order,
and may abandon an image (link too slow, STOP): the host's `ImageAssembler` then drops the partial
image when a chunk of a newer frame id arrives and counts it in ``incomplete``.

The host allocates an image's buffer from its first chunk's claims, so those are checked first: an image
larger than `max_image_bytes` (default `MAX_IMAGE_BYTES`; a host that knows the sensor passes its size), or
whose `chunk_count` cannot hold it in chunks of at most `MAX_CHUNK_DATA` bytes (or exceeds its byte
count), is refused and counted in ``refused``, before any allocation.
"""

from __future__ import annotations

import itertools
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field
from operator import attrgetter

import numpy as np

from eyehil.protocols import kernels
from eyehil.protocols.enums import Eye, PixelFormat
from eyehil.protocols.header import MAX_PAYLOAD, PROTOCOL_VERSION, MessageType, wire_frame
from eyehil.protocols.samples import FrameChunk

MAX_CHUNK_DATA = MAX_PAYLOAD - FrameChunk.STRUCT.size  # 4074 pixel bytes per chunk
MAX_IMAGE_BYTES = 4096 * 4096 * 2  # 32 MiB: the largest image a host reassembles unless told otherwise
_FORMATS = {np.dtype(np.uint8): PixelFormat.MONO8, np.dtype("<u2"): PixelFormat.MONO16}


def _pixels(image: np.ndarray, chunk_data: int) -> tuple[PixelFormat, bytes, int]:
    """The pixel format, little-endian bytes and chunk count of `image`; ValueError if it cannot be sent."""
    if image.ndim != 2 or np.dtype(image.dtype).newbyteorder("<") not in _FORMATS:
        raise ValueError(f"expected a 2-D uint8 or uint16 image, got {image.dtype} {image.shape}")
    if not 0 < chunk_data <= MAX_CHUNK_DATA:
        raise ValueError(f"chunk_data must be in 1..{MAX_CHUNK_DATA}")
    raw = np.ascontiguousarray(image, dtype=image.dtype.newbyteorder("<")).tobytes()
    return _FORMATS[np.dtype(image.dtype).newbyteorder("<")], raw, max(1, -(-len(raw) // chunk_data))


def split_image(
    frame_id: int, eye: Eye, image: np.ndarray, roi_xy: tuple[int, int] = (0, 0), chunk_data: int = MAX_CHUNK_DATA
) -> list[FrameChunk]:
    """FRAME_CHUNKs of a 2-D uint8 or uint16 `image` whose top-left pixel is at `roi_xy` on the sensor."""
    fmt, raw, count = _pixels(image, chunk_data)
    height, width = image.shape
    return [
        FrameChunk(frame_id, eye, fmt, width, height, *roi_xy, k, count, start, raw[start : start + chunk_data])
        for k, start in enumerate(range(0, count * chunk_data, chunk_data))
    ]


class ImageChunks:
    """The FRAME_CHUNKs of one image still to be sent (the device's side): `wire` encodes the next run of them.

    Checked as `split_image` checks (ValueError for an image or roi the protocol cannot carry); `sent` chunks of
    `count` are gone, `done` once all are."""

    def __init__(self, frame_id: int, eye: Eye, image: np.ndarray, roi_xy: tuple[int, int] = (0, 0),
                 chunk_data: int = MAX_CHUNK_DATA) -> None:
        fmt, self._raw, self.count = _pixels(image, chunk_data)
        height, width = image.shape
        self._chunk_data = chunk_data
        self._fields = (frame_id, eye, fmt, width, height, *roi_xy)
        try:  # the chunk head with index and offset 0: the kernel fills them in
            self._head = FrameChunk.STRUCT.pack(*self._fields, 0, self.count, 0)
        except struct.error as exc:
            raise ValueError(f"FrameChunk: {exc}") from exc
        self.sent = 0

    @property
    def done(self) -> bool:
        """Every chunk has been encoded."""
        return self.sent >= self.count

    def wire(self, seq: int, timestamp_us: int, room: int) -> tuple[bytes, int]:
        """The wire bytes of the next chunks, numbered from `seq` (mod 2^32), stamped `timestamp_us`, added while
        fewer than `room` bytes were written (none if `room` <= 0); and how many chunks they hold."""
        first = self.sent
        if not 0 <= timestamp_us < 1 << 64:
            raise ValueError(f"header field out of range: timestamp {timestamp_us} us")
        if kernels.AVAILABLE:
            data, n = kernels.chunk_frames(self._raw, self._head, first, self.count, self._chunk_data, seq,
                                           timestamp_us, PROTOCOL_VERSION, MessageType.FRAME_CHUNK, room)
        else:
            frames: list[bytes] = []
            size, k, step = 0, first, self._chunk_data
            while k < self.count and size < room:
                chunk = FrameChunk(*self._fields, k, self.count, k * step, self._raw[k * step : (k + 1) * step])
                frames.append(wire_frame(MessageType.FRAME_CHUNK, seq + k - first, timestamp_us, chunk.to_payload()))
                size += len(frames[-1])
                k += 1
            data, n = b"".join(frames), k - first
        self.sent += n
        return data, n


@dataclass(frozen=True)
class Image:
    """A reassembled camera image with its frame id, eye and sensor position (px)."""

    frame_id: int
    eye: Eye
    roi_x: int
    roi_y: int
    pixels: np.ndarray  # [height, width] uint8 or uint16


@dataclass
class _Partial:
    """An image being reassembled: its first chunk's geometry, the buffer and the chunks seen."""

    first: FrameChunk
    buffer: np.ndarray  # (image bytes,) uint8, zeros where no chunk has landed; it becomes the image's pixels
    seen: set[int] = field(default_factory=set)


class ImageAssembler:
    """Collects FRAME_CHUNKs (one image in progress per eye) and returns each complete image once."""

    def __init__(self, max_image_bytes: int = MAX_IMAGE_BYTES) -> None:
        """Start with nothing in progress; counters ``complete``, ``incomplete``, ``inconsistent``, ``refused``."""
        self._partial: dict[Eye, _Partial] = {}
        self.max_image_bytes = max_image_bytes
        self.complete = 0
        self.incomplete = 0
        self.inconsistent = 0
        self.refused = 0

    def plausible(self, chunk: FrameChunk) -> bool:
        """True if the image `chunk` claims may be allocated: within the size limit, not empty, and its chunk
        count fits its size."""
        size = chunk.image_size
        needed = -(-size // MAX_CHUNK_DATA)
        return 0 < size <= self.max_image_bytes and needed <= chunk.chunk_count <= size

    def add(self, chunk: FrameChunk) -> Image | None:
        """Take one chunk; return the image it completes, else None."""
        return self._add(chunk, chunk.chunk_index, chunk.offset, chunk.data)

    def add_run(self, first: FrameChunk, rest: Iterable[tuple[int, int, bytes]]) -> list[tuple[int, Image]]:
        """Take `first`, then chunks of its image given as (chunk_index, offset, data) (the same frame id, eye and
        geometry, each inside the image: `eyehil.protocols.stream.ChunkRun`), as `add` would one by one; return the
        images they complete, each with the position in the run (`first` 0) of the chunk that completed it."""
        pieces = itertools.chain([(first.chunk_index, first.offset, first.data)], rest)
        images = [(k, self._add(first, index, offset, data)) for k, (index, offset, data) in enumerate(pieces)]
        return [(k, image) for k, image in images if image is not None]

    def _add(self, chunk: FrameChunk, index: int, offset: int, data: bytes) -> Image | None:
        """`add` of a chunk with `chunk`'s frame id, eye and geometry, and the index, offset and data given."""
        part = self._partial.get(chunk.eye)
        if part is not None and part.first.frame_id != chunk.frame_id:
            self.incomplete += 1
            del self._partial[chunk.eye]
            part = None
        if part is None:
            if not self.plausible(chunk):
                self.refused += 1
                return None
            part = _Partial(chunk, np.zeros(chunk.image_size, np.uint8))
            self._partial[chunk.eye] = part
        elif part.first is not chunk and not _same_geometry(part.first, chunk):
            self.inconsistent += 1
            del self._partial[chunk.eye]
            return None
        part.buffer.data[offset : offset + len(data)] = data
        part.seen.add(index)
        return self._finish(chunk.eye) if len(part.seen) == chunk.chunk_count else None

    def _finish(self, eye: Eye) -> Image:
        """Pop the completed image of `eye` and wrap it as an `Image`."""
        part = self._partial.pop(eye)
        c = part.first
        dtype = np.uint8 if c.pixel_format is PixelFormat.MONO8 else np.dtype("<u2")
        pixels = part.buffer.view(dtype).reshape(c.height, c.width)  # no copy: the buffer is the image's alone
        pixels.flags.writeable = False
        self.complete += 1
        return Image(c.frame_id, c.eye, c.roi_x, c.roi_y, pixels)


_GEOMETRY = attrgetter("pixel_format", "width", "height", "roi_x", "roi_y", "chunk_count")  # a chunk's image layout


def _same_geometry(a: FrameChunk, b: FrameChunk) -> bool:
    """True if two chunks describe the same image layout."""
    return _GEOMETRY(a) == _GEOMETRY(b)
