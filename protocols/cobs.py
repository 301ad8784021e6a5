"""Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM Trans. Networking 7(2), 1999).

COBS rewrites a byte string so that it contains no 0x00; a 0x00 can then delimit frames on a byte
stream, and a receiver that lost bytes resynchronises at the next 0x00. The encoded string is a
sequence of blocks, each a code byte n (1..255) followed by n - 1 non-zero data bytes:

- n < 0xFF: the n - 1 data bytes are followed by a 0x00 in the decoded data, except after the last block;
- n = 0xFF: 254 data bytes, not followed by 0x00.

Conceptually the encoder appends a 0x00 to the data, splits it after every 0x00 (and after runs of 254
non-zero bytes) and drops the final 0x00 again. This implementation does not emit an empty trailing
block after a final run of exactly 254 non-zero bytes (the Wikipedia form, one byte shorter than the
paper's); `decode` accepts both forms. Overhead: at most ceil(n / 254) bytes for n >= 1 bytes, and one
byte for the empty string.

Known answers (hex): ``00`` -> ``01 01``; ``00 00`` -> ``01 01 01``; ``11 22 00 33`` -> ``03 11 22 02 33``;
``11 22 33 44`` -> ``05 11 22 33 44``; ``11 00 00 00`` -> ``02 11 01 01 01``; 254 bytes ``01..FE`` ->
``FF 01..FE``; 255 bytes ``01..FF`` -> ``FF 01..FE 02 FF``. The frame delimiter 0x00 is not part of
these strings: `eyehil.protocols.framing` adds it.

`encode` and `decode` run the compiled kernels (`eyehil.protocols.kernels`) where they can be had, else the Python
fast paths `encode_python` and `decode_python`: a few Python operations per piece between two zeros, while a run
of full blocks (camera images have long zero-free runs) is cut by one struct call and decoded by one strided
deletion. `encode_reference` and `decode_reference` are the block-at-a-time forms that follow the definition
above, kept as the reference the others are tested against. Every invalid string goes to `decode_reference`, so
that it raises the same `CobsDecodeError`, with the same message, whichever path found it invalid.
"""

from __future__ import annotations

import struct

from eyehil.protocols import kernels
from eyehil.protocols.errors import CobsDecodeError

MAX_BLOCK = 254  # data bytes in one block of code 0xFF
_FULL = MAX_BLOCK + 1  # bytes of one encoded 0xFF block (code + data)
_CODE_AFTER = tuple(bytes((n + 1,)) for n in range(MAX_BLOCK))  # the code byte of a block of n < 254 data bytes
_GROUP = 16  # full blocks cut from a piece by one struct call
_RUN = 64  # 0xFF blocks at most decoded as one run (bounds the strided slice that finds them)
_BLOCKS = tuple(struct.Struct(f"{MAX_BLOCK}s" * k) for k in range(_GROUP + 1))  # k full blocks' data bytes


def max_encoded_size(n: int) -> int:
    """Largest COBS encoding of `n` bytes (without the delimiter)."""
    return max(1, n + -(-n // MAX_BLOCK))


def encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode `data`; the result contains no 0x00 byte. Same bytes as `encode_reference`, faster."""
    return kernels.cobs_encode(data) if kernels.AVAILABLE else encode_python(data)


def decode(encoded: bytes | bytearray | memoryview) -> bytes:
    """Decode one COBS string (without its delimiter); raise `CobsDecodeError` if it is not valid COBS.

    Same result, and the same error, as `decode_reference`, faster.
    """
    if not kernels.AVAILABLE:
        return decode_python(encoded)
    out = kernels.cobs_decode(encoded)
    return decode_reference(encoded) if out is None else out  # invalid: the reference finds the first fault


def encode_python(data: bytes | bytearray | memoryview) -> bytes:
    """`encode` without the compiled kernel.

    The output is `data` behind one code byte, with each 0x00 replaced by the code byte of the piece after it, as long
    as no zero-free piece reaches 254 bytes: those codes are patched in place. A longer piece is cut into 0xFF
    blocks (`_splice_full_blocks`) and spliced in.
    """
    src = bytes(data)
    out = bytearray(b"\x01") + src  # out[k + 1] = src[k]; out[s] codes the piece that starts at src[s]
    parts: list[bytes | bytearray] = []  # only when a piece needs 0xFF blocks
    done = start = 0  # out[:done] is in parts; the current piece starts at src[start]
    find = src.find
    while (zero := find(0, start)) >= 0:
        if zero - start < MAX_BLOCK:
            out[start] = zero - start + 1
        else:
            done = _splice_full_blocks(src, start, zero, out, done, parts)
        start = zero + 1
    if len(src) - start < MAX_BLOCK:
        out[start] = len(src) - start + 1
    else:
        done = _splice_full_blocks(src, start, len(src), out, done, parts)
        if (len(src) - start) % MAX_BLOCK == 0:  # the Wikipedia form: no empty block after a final run of full blocks
            del parts[-2:]
    if not parts:
        return bytes(out)
    parts.append(out[done:])
    return b"".join(parts)


def _splice_full_blocks(
    src: bytes, start: int, end: int, out: bytearray, done: int, parts: list[bytes | bytearray]
) -> int:
    """Append to `parts` the bytes of `out` from `done` up to the piece src[start:end] of >= 254 bytes, then that
    piece's blocks (its 0xFF blocks, the code of its last block and that block's < 254 bytes); return the offset
    in `out` after the piece."""
    count = (end - start) // MAX_BLOCK
    blocks = [b""]  # joined with 0xFF: a code byte before each block
    for first in range(0, count, _GROUP):
        blocks += _BLOCKS[min(_GROUP, count - first)].unpack_from(src, start + first * MAX_BLOCK)
    rest = src[start + count * MAX_BLOCK : end]
    parts += (out[done:start], b"\xff".join(blocks), _CODE_AFTER[len(rest)], rest)
    return end + 1


def decode_python(encoded: bytes | bytearray | memoryview) -> bytes:
    """`decode` without the compiled kernel."""
    src = bytes(encoded)
    if not src or 0 in src:
        return decode_reference(src)  # invalid: the reference finds the first fault and names it
    return _decode_zero_free(src)


def _decode_zero_free(src: bytes) -> bytes:
    """Decode a non-empty COBS string that contains no 0x00.

    The decoded bytes are `src` without its code bytes, except that a code byte after a block of code < 0xFF
    stands where that block's trailing 0x00 goes: those are zeroed in place, the others (the first code byte,
    and those after 0xFF blocks) deleted, each run of 0xFF blocks by one strided deletion.
    """
    n = len(src)
    buf = bytearray(src)
    drops: list[slice] = []  # code bytes deleted after 0xFF blocks, in increasing order
    i = 0
    while i < n:
        code = src[i]
        if code == 0xFF:
            end = _full_run_end(src, i)
            drops.append(slice(i + _FULL, end + 1, _FULL))
        else:
            end = i + code
            if end > n:
                raise CobsDecodeError(f"block at offset {i} needs {code - 1} bytes, {n - i - 1} left")
            if end < n:
                buf[end] = 0
        i = end
    for drop in reversed(drops):
        del buf[drop]
    del buf[0]
    return bytes(buf)


def _full_run_end(src: bytes, i: int) -> int:
    """Offset after the run of consecutive 0xFF blocks starting at `i` in the zero-free `src` (at most `_RUN` of them:
    a longer run continues at the offset returned).

    The code bytes of such a run sit every 255 bytes; raise `CobsDecodeError` if its last block is truncated.
    """
    codes = src[i : i + _RUN * _FULL : _FULL]
    count = len(codes) - len(codes.lstrip(b"\xff"))
    end = i + count * _FULL
    if end > len(src):
        last = end - _FULL
        raise CobsDecodeError(f"block at offset {last} needs {MAX_BLOCK} bytes, {len(src) - last - 1} left")
    return end


def _encode_piece(piece: bytes, out: bytearray, last: bool) -> None:
    """Append the blocks for one zero-free `piece`; it is followed by a 0x00 unless it is the `last`."""
    n = len(piece)
    full = n // MAX_BLOCK
    for k in range(full):
        out.append(0xFF)
        out += piece[k * MAX_BLOCK : (k + 1) * MAX_BLOCK]
    rest = piece[full * MAX_BLOCK :]
    if rest or not last or n == 0:
        out.append(len(rest) + 1)
        out += rest


def encode_reference(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode `data` piece by piece and block by block, as defined above (the reference for `encode`)."""
    pieces = bytes(data).split(b"\x00")
    out = bytearray()
    for i, piece in enumerate(pieces):
        _encode_piece(piece, out, last=i == len(pieces) - 1)
    return bytes(out)


def decode_reference(encoded: bytes | bytearray | memoryview) -> bytes:
    """Decode one COBS string block by block (the reference for `decode`); raise `CobsDecodeError` if invalid."""
    src = bytes(encoded)
    if not src:
        raise CobsDecodeError("empty COBS string (the encoding of b'' is 01)")
    out = bytearray()
    i, n = 0, len(src)
    while i < n:
        code = src[i]
        if code == 0:
            raise CobsDecodeError(f"zero byte at offset {i} inside a COBS string")
        end = i + code
        if end > n:
            raise CobsDecodeError(f"block at offset {i} needs {code - 1} bytes, {n - i - 1} left")
        block = src[i + 1 : end]
        if 0 in block:
            raise CobsDecodeError(f"zero byte inside the block at offset {i}")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
