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
"""

from __future__ import annotations

from eyehil.protocols.errors import CobsDecodeError

MAX_BLOCK = 254  # data bytes in one block of code 0xFF


def max_encoded_size(n: int) -> int:
    """Largest COBS encoding of `n` bytes (without the delimiter)."""
    return max(1, n + -(-n // MAX_BLOCK))


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


def encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode `data`; the result contains no 0x00 byte."""
    pieces = bytes(data).split(b"\x00")
    out = bytearray()
    for i, piece in enumerate(pieces):
        _encode_piece(piece, out, last=i == len(pieces) - 1)
    return bytes(out)


def decode(encoded: bytes | bytearray | memoryview) -> bytes:
    """Decode one COBS string (without its delimiter); raise `CobsDecodeError` if it is not valid COBS."""
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
