"""The framing's compiled kernels (`kernels.c`): CRC-16/CCITT-FALSE and COBS, 3-10 times faster than Python.

`eyehil.protocols.crc.crc16`, `eyehil.protocols.cobs.encode` and `.decode` use them when they can be had, and
their Python fast paths otherwise; `eyehil.protocols.header.wire_frame` uses `frame_encode` (CRC, COBS and
delimiter in one call) in place of `pack_frame` then `encode_frame`; `eyehil.protocols.images.ImageChunks` uses
`chunk_frames` (a run of an image's FRAME_CHUNKs, header to delimiter, in one call); and
`eyehil.protocols.stream.NativeReceiver` uses `decode_frames` (every whole frame of a read COBS-decoded and checked
in one call). Both paths give the same bytes and the same events (tests/test_framing.py, test_protocol_batch.py
and test_protocol_stream.py check each against the references). The CRC folds 64 bytes and more by carry-less
multiplication where the processor can (`FOLDING`). The library is built with the system's C compiler on first
use (`eyehil.cbuild`: once per machine, cached). Set EYEHIL_PURE_PYTHON=1 to run without it; `REASON` says why it
is not in use.

Every function takes bytes-like input and bounds its output buffer by the input's length, so no peer's bytes can
write past it (`kernels.c`).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

from eyehil.cbuild import load

SOURCE = Path(__file__).with_name("kernels.c")
MAX_BLOCK = 254  # COBS data bytes in a 0xFF block


def _declare(lib: ctypes.CDLL) -> None:
    lib.eyehil_crc16.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint16)
    lib.eyehil_crc16.restype = ctypes.c_uint16
    lib.eyehil_crc16_folding.argtypes = ()
    lib.eyehil_crc16_folding.restype = ctypes.c_int
    lib.eyehil_cobs_encode.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    lib.eyehil_cobs_encode.restype = ctypes.c_size_t
    lib.eyehil_cobs_decode.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    lib.eyehil_cobs_decode.restype = ctypes.c_long
    lib.eyehil_frame_encode.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    lib.eyehil_frame_encode.restype = ctypes.c_size_t
    lib.eyehil_chunk_frames.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_uint32,
                                        ctypes.c_uint32, ctypes.c_size_t, ctypes.c_uint32, ctypes.c_uint64,
                                        ctypes.c_uint8, ctypes.c_uint8, ctypes.c_long, ctypes.c_char_p,
                                        ctypes.c_size_t, ctypes.POINTER(ctypes.c_uint32))
    lib.eyehil_chunk_frames.restype = ctypes.c_size_t
    lib.eyehil_decode_frames.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t,
                                         ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                                         ctypes.POINTER(ctypes.c_size_t))
    lib.eyehil_decode_frames.restype = ctypes.c_size_t


_LIB, REASON = load(SOURCE, _declare)
AVAILABLE = _LIB is not None
#: The CRC of 64 bytes or more folds blocks by carry-less multiplication (x86-64 with PCLMUL: about ten times the
#: tables' speed); elsewhere the tables serve every length.
FOLDING = AVAILABLE and bool(_LIB.eyehil_crc16_folding())
#: The longest frame (header, payload, CRC) `frame_encode` takes: `eyehil.protocols.framing.MAX_FRAME_SIZE`.
MAX_FRAME = ctypes.c_size_t.in_dll(_LIB, "eyehil_max_frame").value if AVAILABLE else 0


def crc16(data: bytes | bytearray | memoryview, value: int) -> int:
    """CRC-16/CCITT-FALSE of `data`, continuing from the register `value`."""
    src = data if type(data) is bytes else bytes(data)
    return _LIB.eyehil_crc16(src, len(src), value & 0xFFFF)


def cobs_encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS encoding of `data`."""
    src = data if type(data) is bytes else bytes(data)
    out = ctypes.create_string_buffer(len(src) + len(src) // MAX_BLOCK + 1)
    return ctypes.string_at(out, _LIB.eyehil_cobs_encode(src, len(src), out))


def cobs_decode(encoded: bytes | bytearray | memoryview) -> bytes | None:
    """The bytes one COBS string (no delimiter) decodes to, or None if it is not valid COBS."""
    src = encoded if type(encoded) is bytes else bytes(encoded)
    out = ctypes.create_string_buffer(max(1, len(src)))
    n = _LIB.eyehil_cobs_decode(src, len(src), out)
    return None if n < 0 else ctypes.string_at(out, n)


FRAMES_PER_CALL = 256  # frames `decode_frames` checks per kernel call
RECORD = 10  # int64s in a frame's record (kernels.c FRAME_RECORD)


class FrameBuffers:
    """What `decode_frames` writes into, kept by its caller between calls (grown as needed; not thread-safe)."""

    def __init__(self) -> None:
        self.decoded = ctypes.create_string_buffer(1)
        self.records = (ctypes.c_int64 * (RECORD * FRAMES_PER_CALL))()
        self.record_view = memoryview(self.records).cast("B").cast("q")

    def room(self, size: int) -> memoryview:
        """A view of the decoded-frames buffer, at least `size` bytes long."""
        if len(self.decoded) < size:
            self.decoded = ctypes.create_string_buffer(max(size, 2 * len(self.decoded)))
        return memoryview(self.decoded).cast("B")


def decode_frames(data: bytes, max_encoded: int, max_frame: int, buffers: FrameBuffers | None = None,
                  start: int = 0, end: int | None = None) -> tuple[memoryview, list[list[int]]]:
    """The frames of ``data[start:end]`` (read in place, not copied), each a non-empty run of bytes ending at a 0x00
    (the part ends at one): a view of the buffer their COBS decodings are in (`buffers.decoded`, valid until the next
    call), and per run a record [start (in `data`), length (of the run), offset, size (of its frame in the buffer; -1:
    not valid COBS, or longer than `max_encoded`), verdict (0: size within [20, `max_frame`], CRC, magic and payload
    length pass, and the header fields follow; else 1), version, type, seq, timestamp_us (as a signed 64-bit number),
    payload_len]. ValueError if ``0 <= start <= end <= len(data)`` does not hold."""
    src = data if type(data) is bytes else bytes(data)
    end = len(src) if end is None else end
    if not 0 <= start <= end <= len(src):
        raise ValueError(f"[{start}, {end}) is not a part of {len(src)} bytes")
    buffers = buffers or FrameBuffers()
    view = buffers.room(end - start)
    base = ctypes.cast(ctypes.c_char_p(src), ctypes.c_void_p).value  # `src` stays referenced while it is read
    out = ctypes.addressof(buffers.decoded)
    consumed = ctypes.c_size_t()
    rows: list[list[int]] = []
    taken, dst = start, 0
    while taken < end:
        count = _LIB.eyehil_decode_frames(base + taken, end - taken, max_encoded, max_frame, out + dst,
                                          buffers.records, FRAMES_PER_CALL, ctypes.byref(consumed))
        block = buffers.record_view[: RECORD * count].tolist()
        at = dst  # this call's frames were written from here on
        for k in range(count):
            row = block[RECORD * k : RECORD * (k + 1)]
            row[0] += taken
            row[2] += at
            rows.append(row)
            dst = row[2] + max(row[3], 0)
        taken += consumed.value
        if count < FRAMES_PER_CALL:
            break
    return view, rows


def frame_encode(raw: bytes) -> bytes:
    """The wire bytes of the frame whose header and payload are `raw`: COBS of `raw` and its CRC-16 (low byte
    first), then the 0x00 delimiter. Raises ValueError if the frame would exceed `MAX_FRAME` bytes."""
    src = raw if type(raw) is bytes else bytes(raw)
    n = len(src) + 2
    out = ctypes.create_string_buffer(n + n // MAX_BLOCK + 2)
    size = _LIB.eyehil_frame_encode(src, len(src), out)
    if size == 0:
        raise ValueError(f"frame of {n} bytes exceeds the maximum of {MAX_FRAME}")
    return ctypes.string_at(out, size)


def chunk_frames(pixels: bytes, head: bytes, first: int, count: int, chunk_data: int, seq: int, timestamp_us: int,
                 version: int, msg_type: int, room: int) -> tuple[bytes, int]:
    """The wire bytes of chunks `first`, `first` + 1, ... of the image `pixels` (`count` chunks of `chunk_data` bytes;
    `head` the 22-byte chunk head, its index and offset filled in per chunk), numbered from `seq`, while fewer than
    `room` bytes were written; and how many chunks they hold. ValueError if a chunk would not fit a frame."""
    frame = 18 + 22 + chunk_data + 2
    cap = min(count - first, max(0, room) // frame + 1) * (frame + frame // MAX_BLOCK + 2)
    out = ctypes.create_string_buffer(max(1, cap))
    released = ctypes.c_uint32()
    size = _LIB.eyehil_chunk_frames(pixels, len(pixels), head, first, count, chunk_data, seq & 0xFFFFFFFF,
                                    timestamp_us, version, msg_type, room, out, cap, ctypes.byref(released))
    if size == 0 and room > 0 and first < count:
        raise ValueError(f"chunks of {chunk_data} bytes do not fit a frame, or {count} chunks miss the image")
    return ctypes.string_at(out, size), released.value
