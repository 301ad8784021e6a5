"""Python binding (ctypes) to the firmware's C feature extractor (`extract.c` through `extract_flat.c`).

`build_library(build_dir)` runs ``make lib`` into `build_dir` and returns the shared library's path;
`Extractor(path)` loads it; `Extractor.extract(image, ...)` runs the C extractor on one 8-bit image (a
window of the sensor whose top-left pixel is sensor pixel `origin`) and returns an `Extraction` in
full-sensor px (OpenCV convention), angles in degrees. Not thread-safe: the library has one static workspace.
"""

from __future__ import annotations

import ctypes
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SOURCES = Path(__file__).resolve().parent
LIBRARY = "libeyehil_extract.so"
MAX_EYES, MAX_LEDS = 2, 2
EYE_FIELDS = 10 + 4 * MAX_LEDS

PUPIL_DETECTED, PUPIL_PARTIAL, PUPIL_BLINK = 0x01, 0x02, 0x08
GLINT_VALID, GLINT_SATURATED, GLINT_ON_PUPIL_EDGE, GLINT_AMBIGUOUS = 0x01, 0x02, 0x04, 0x08


def build_library(build_dir: Path, cflags: str | None = None) -> Path:
    """``make lib`` into `build_dir` (optionally with CFLAGS); the library's path. RuntimeError on failure."""
    args = ["make", "-C", str(SOURCES), f"BUILD={build_dir}", "lib"]
    if cflags is not None:
        args.append(f"CFLAGS={cflags}")
    result = subprocess.run(args, capture_output=True, text=True, timeout=120, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"extractor build failed:\n{result.stdout}\n{result.stderr}")
    return Path(build_dir) / LIBRARY


@dataclass(frozen=True)
class EyeFound:
    """One pupil and its glints (sensor px, degrees); glint arrays (MAX_LEDS, ...) in lit-LED order."""

    flags: int
    centre_px: np.ndarray
    axes_px: np.ndarray
    angle_deg: float
    confidence: float
    edge_points: int
    fit_rms_px: float
    glint_count: int
    glint_led: np.ndarray
    glint_flags: np.ndarray
    glint_px: np.ndarray


@dataclass(frozen=True)
class Extraction:
    """What the C extractor found in one image: pupils left to right, blink, image flags and counts."""

    flags: int
    eyes: tuple[EyeFound, ...]
    blink: bool
    iris_px: int
    dark_regions: int
    bright_regions: int


class Extractor:
    """The loaded library; see the module docstring."""

    def __init__(self, path: Path) -> None:
        self._lib = ctypes.CDLL(str(path))
        self._fn = self._lib.ex_extract_flat
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [ctypes.c_void_p, *[ctypes.c_int] * 7, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
        self.size = int(self._lib.ex_flat_size())
        self._out = np.zeros(self.size, np.float32)

    def extract(self, image: np.ndarray, *, origin: tuple[int, int] = (0, 0), lit_mask: int = 0b11, max_eyes: int = 1,
                led_dir: np.ndarray | None = None, repeats: int = 1) -> Extraction:
        """Run the extractor on `image` (H, W) uint8; `led_dir` (MAX_LEDS, 2): each LED's image direction."""
        image = np.ascontiguousarray(image, dtype=np.uint8)
        if image.ndim != 2:
            raise ValueError(f"expected a 2-D 8-bit image, got shape {image.shape}")
        dirs = None
        if led_dir is not None:
            dirs = np.zeros((MAX_LEDS, 2), np.float32)
            dirs[: len(led_dir)] = np.asarray(led_dir, np.float32)[:MAX_LEDS]
        h, w = image.shape
        status = self._fn(image.ctypes.data, w, h, w, int(origin[0]), int(origin[1]), lit_mask, max_eyes,
                          None if dirs is None else dirs.ctypes.data, repeats, self._out.ctypes.data)
        if status != 0:
            raise ValueError(f"ex_extract refused the arguments (status {status})")
        return _unpack(self._out)


def _unpack(out: np.ndarray) -> Extraction:
    eyes = []
    for e in range(int(out[1])):
        o = out[6 + e * EYE_FIELDS: 6 + (e + 1) * EYE_FIELDS].astype(float)
        g = o[10:].reshape(MAX_LEDS, 4)
        eyes.append(EyeFound(int(o[0]), o[1:3].copy(), o[3:5].copy(), float(o[5]), float(o[6]), int(o[7]),
                             float(o[8]), int(o[9]), g[:, 0].astype(int), g[:, 1].astype(int), g[:, 2:4].copy()))
    return Extraction(int(out[0]), tuple(eyes), bool(out[2]), int(out[3]), int(out[4]), int(out[5]))
