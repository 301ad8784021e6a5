"""The renderer's compiled kernels (`kernels.c`): the sensor's noise over a canvas in one pass, and the counter noise's
draws (`eyehil.emulator.render.noise`).

`eyehil.emulator.render.renderer.expose` uses `expose_flat` for a canvas that is flat outside its boxes (what
`expose_canvas` passes) when it can be had, and its numpy path otherwise; both give the same image, bit for bit
(tests/test_render.py). On a 320 x 240 region it takes 58 us where numpy takes 124 (the uniform draws, 36 us,
are numpy's either way: docs/benchmarks.md). With counter noise (`expose_counter`) the draws are computed in the
same pass and never stored: 101-108 us for a 320 x 240 image with a 120 x 200 box, where drawing them first
(`counter_draws`, 25 us) and then `expose_flat` took 109-115.
Built with the system's C compiler on first use (`eyehil.cbuild`, cached); EYEHIL_PURE_PYTHON=1 runs without it,
and `REASON` says why it is not in use.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from eyehil.cbuild import load

SOURCE = Path(__file__).with_name("kernels.c")
FLAGS = ("-O2", "-ffp-contract=off")  # one IEEE float32 operation at a time, as numpy computes them

Box = tuple[int, int, int, int]  # canvas rows [r0, r1), columns [c0, c1) (`eyehil.emulator.render.draw.Box`)


def _declare(lib: ctypes.CDLL) -> None:
    p, size, f = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_float
    lib.eyehil_expose.argtypes = (p, p, size, size, p, p, size, p, f, f, f, ctypes.c_int, p)
    lib.eyehil_expose.restype = None
    lib.eyehil_expose_counter.argtypes = (p, ctypes.c_uint64, size, size, p, p, size, p, f, f, f, ctypes.c_int, p)
    lib.eyehil_expose_counter.restype = None
    lib.eyehil_counter_draws.argtypes = (ctypes.c_uint64, size, p)
    lib.eyehil_counter_draws.restype = None


_LIB, REASON = load(SOURCE, _declare, FLAGS)
AVAILABLE = _LIB is not None


def expose_flat(signal: np.ndarray, uniform: np.ndarray, flat: np.ndarray, boxes: Sequence[Box | None],
                normal: np.ndarray, k: np.float32, read2: np.float32, hi: np.float32) -> np.ndarray:
    """The image of `signal` (H, W) float32 DN with one uniform 16-bit draw per pixel (`uniform`, (H, W)): outside
    `boxes` the entry of `flat` (65,536 outcomes of the canvas's flat level, uint8 or uint16) for the draw, inside
    them sqrt(max(signal k, 0) + read2) * normal[draw] added, rounded and clipped to [0, hi]. `signal` is not
    changed."""
    signal = np.ascontiguousarray(signal, np.float32)
    uniform = np.ascontiguousarray(uniform, np.uint16)
    if uniform.shape != signal.shape or signal.ndim != 2:
        raise ValueError(f"signal {signal.shape} and draws {uniform.shape} must be the same 2-D shape")
    return _expose(_LIB.eyehil_expose, signal, uniform.ctypes.data, flat, boxes, normal, k, read2, hi)


def expose_counter(signal: np.ndarray, key: int, flat: np.ndarray, boxes: Sequence[Box | None], normal: np.ndarray,
                   k: np.float32, read2: np.float32, hi: np.float32) -> np.ndarray:
    """`expose_flat` with the draws of counter noise `key` (`noise.CounterNoise`), computed as they are used."""
    signal = np.ascontiguousarray(signal, np.float32)
    if signal.ndim != 2:
        raise ValueError(f"signal {signal.shape} must be 2-D")
    return _expose(_LIB.eyehil_expose_counter, signal, ctypes.c_uint64(key), flat, boxes, normal, k, read2, hi)


def _expose(kernel, signal: np.ndarray, draws, flat: np.ndarray, boxes: Sequence[Box | None], normal: np.ndarray,
            k: np.float32, read2: np.float32, hi: np.float32) -> np.ndarray:
    """Call `kernel` (eyehil_expose or eyehil_expose_counter) on a checked 2-D float32 `signal` and its `draws`."""
    if flat.shape != (65536,) or flat.dtype not in (np.uint8, np.uint16) or normal.shape != (65536,):
        raise ValueError("flat and normal are tables of the 65,536 draws (flat uint8 or uint16)")
    flat = np.ascontiguousarray(flat)
    normal = np.ascontiguousarray(normal, np.float32)
    table = np.array([b for b in boxes if b is not None], np.int64).reshape(-1, 4)
    out = np.empty(signal.shape, flat.dtype)
    rows, cols = signal.shape
    kernel(signal.ctypes.data, draws, rows, cols, flat.ctypes.data, table.ctypes.data, len(table),
           normal.ctypes.data, float(k), float(read2), float(hi), int(flat.dtype == np.uint16), out.ctypes.data)
    return out


def counter_draws(key: int, out: np.ndarray) -> np.ndarray:
    """Fill `out` (n,) uint16, contiguous, with the draws 0 .. n-1 of counter noise `key` (`noise.CounterNoise`)."""
    if out.dtype != np.uint16 or out.ndim != 1 or not out.flags.c_contiguous:
        raise ValueError("counter draws go into a contiguous 1-D uint16 array")
    _LIB.eyehil_counter_draws(key, out.size, out.ctypes.data)
    return out
