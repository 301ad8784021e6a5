"""CRC-16/CCITT-FALSE, the frame check of the eyehil native protocol.

Parameters (Rocksoft model): width 16, polynomial 0x1021 (x^16 + x^12 + x^5 + 1), initial value 0xFFFF,
input and output not reflected, final XOR 0x0000. Check value: CRC of the ASCII bytes b"123456789" is
0x29B1. `crc16` is the compiled kernel (`eyehil.protocols.kernels`, sliced by 8 bytes) where it can be had, else
`binascii.crc_hqx(data, 0xFFFF)`, which computes exactly this; `crc16_bitwise` is the textbook bit-at-a-time form
a firmware author can port, kept as the reference both are tested against.
On the wire the CRC is sent little-endian (low byte first), like every other field.
"""

from __future__ import annotations

import binascii

from eyehil.protocols import kernels

CRC16_POLY = 0x1021
CRC16_INIT = 0xFFFF
CRC16_CHECK = 0x29B1  # crc16(b"123456789")
CRC_SIZE = 2


def crc16(data: bytes | bytearray | memoryview, value: int = CRC16_INIT) -> int:
    """CRC-16/CCITT-FALSE of `data`; pass a previous result as `value` to continue over more data."""
    return _crc16(data, value)


_crc16 = kernels.crc16 if kernels.AVAILABLE else binascii.crc_hqx


def crc16_bitwise(data: bytes | bytearray | memoryview, value: int = CRC16_INIT) -> int:
    """Reference implementation: shift each byte in MSB first, XOR the polynomial on carry."""
    crc = value & 0xFFFF
    for byte in bytes(data):
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ CRC16_POLY) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc
