"""The framing's compiled kernels (`kernels.c`): CRC-16/CCITT-FALSE and COBS, 10-20 times faster than Python.

`eyehil.protocols.crc.crc16`, `eyehil.protocols.cobs.encode` and `.decode` use them when they can be had, and
their Python fast paths otherwise; both give the same bytes (tests/test_framing.py checks each against the
references). The library is built with the system's C compiler on first use (`eyehil.cbuild`: once per
machine, cached). Set EYEHIL_PURE_PYTHON=1 to run without it; `REASON` says why it is not in use.

Every function takes bytes-like input and bounds its output buffer by the input's length, so no peer's bytes can
write past it (`kernels.c`).
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

from eyehil.cbuild import BuildUnavailableError, build

SOURCE = Path(__file__).with_name("kernels.c")
MAX_BLOCK = 254  # COBS data bytes in a 0xFF block


def _load() -> tuple[ctypes.CDLL | None, str]:
    if os.environ.get("EYEHIL_PURE_PYTHON"):
        return None, "EYEHIL_PURE_PYTHON is set"
    try:
        lib = ctypes.CDLL(str(build(SOURCE, flags=("-O2",))))
    except (BuildUnavailableError, OSError) as exc:
        return None, str(exc)
    lib.eyehil_crc16.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint16)
    lib.eyehil_crc16.restype = ctypes.c_uint16
    lib.eyehil_cobs_encode.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    lib.eyehil_cobs_encode.restype = ctypes.c_size_t
    lib.eyehil_cobs_decode.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    lib.eyehil_cobs_decode.restype = ctypes.c_long
    return lib, ""


_LIB, REASON = _load()
AVAILABLE = _LIB is not None


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
