"""What the page receives: JSON-ready dicts of samples and calibrations, and the binary image message.

Pure functions, no I/O. Image coordinates are full-sensor pixels (OpenCV convention: origin at the
top-left pixel centre, x right, y down), as on the wire; screen positions are STIMULUS mm (from the
top-left corner as the subject sees it, x right, y down). Non-finite numbers become None (JSON null).

Image message (binary WebSocket frame): ``<I`` header length, the UTF-8 JSON header (eye, frame_id,
roi_x, roi_y, width, height, device_us, record: the features of that exposure
for the overlay, or null; truth: the device's record when the host detected, or null), then the image encoded as JPEG.
"""

from __future__ import annotations

import json
import math
import struct

import cv2
import numpy as np

from eyehil.drivers.calibration import Result, screen_to_stimulus
from eyehil.drivers.gaze.geometry import Screen
from eyehil.protocols.enums import Capability, Eye, GlintFlags, PupilFlags
from eyehil.protocols.replies import DeviceInfo
from eyehil.protocols.samples import EyeFeatures

HEADER_LENGTH = struct.Struct("<I")
JPEG_QUALITY = 85


def number(value: float, digits: int = 3) -> float | None:
    """`value` rounded, or None if it is not finite."""
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def eye_record(record: EyeFeatures) -> dict:
    """One eye's FEATURES record for the overlay: pupil ellipse (px, deg), confidence, flags, glints by LED."""
    detected = PupilFlags.DETECTED in record.flags and PupilFlags.BLINK not in record.flags
    return {
        "eye": Eye(record.eye).name.lower(),
        "detected": bool(detected),
        "blink": bool(PupilFlags.BLINK in record.flags),
        "x": number(record.centre_x), "y": number(record.centre_y),
        "a": number(record.axis_a), "b": number(record.axis_b), "angle": number(record.angle_deg, 2),
        "confidence": number(record.confidence),
        "glints": [{"led": int(g.led), "x": number(g.x), "y": number(g.y)}
                   for g in record.glints if GlintFlags.VALID in g.flags],
    }


def confidence_of(record: EyeFeatures | None) -> float | None:
    """The record's confidence, 0 when the pupil is missing, None without a record."""
    if record is None:
        return None
    detected = PupilFlags.DETECTED in record.flags and PupilFlags.BLINK not in record.flags
    return number(record.confidence if detected else 0.0)


def xy(point: np.ndarray | tuple[float, float] | None) -> list[float | None] | None:
    """A point as [x, y] (None if absent or not finite)."""
    if point is None:
        return None
    x, y = (number(v, 2) for v in point)
    return None if x is None or y is None else [x, y]


def image_message(eye: Eye, frame_id: int, roi_xy: tuple[int, int], pixels: np.ndarray, device_us: int,
                  record: dict | None = None, truth: dict | None = None) -> bytes:
    """The binary message of one camera image (see the module docstring); MONO16 is scaled to 8 bits. `record`:
    the eye's features of the same exposure (`eye_record`), drawn over this image; `truth`: the device's own record
    of it when the host detected `record` (on the emulator: the ground truth)."""
    if pixels.dtype != np.uint8:
        pixels = (pixels >> 8).astype(np.uint8)
    ok, jpeg = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("JPEG encoding failed")
    header = json.dumps({"eye": Eye(eye).name.lower(), "frame_id": int(frame_id), "roi_x": int(roi_xy[0]),
                         "roi_y": int(roi_xy[1]), "width": int(pixels.shape[1]), "height": int(pixels.shape[0]),
                         "device_us": int(device_us), "record": record, "truth": truth}, allow_nan=False).encode()
    return HEADER_LENGTH.pack(len(header)) + header + jpeg.tobytes()


def calibration_message(result: Result, screen: Screen) -> dict:
    """The "calibration" message: validation targets, estimates (STIMULUS mm) and errors (deg) of `result`."""
    targets = screen_to_stimulus(screen, result.plan.validation_mm)
    estimates = screen_to_stimulus(screen, result.estimates_mm)
    points = [{"target": xy(t), "estimate": xy(e), "error_deg": number(err)}
              for t, e, err in zip(targets, estimates, result.errors_deg, strict=True)]
    return {"type": "calibration", "method": result.method, "ok": True, "error": None,
            "mean_error_deg": number(result.mean_error_deg), "points": points,
            "calibration_targets": [xy(p) for p in screen_to_stimulus(screen, result.plan.calibration_mm)]}


def hello_message(info: DeviceInfo, url: str, stream: str, screen: Screen | None, blink: bool) -> dict:
    """The "hello" message: the device as DEVICE_INFO describes it, the stream mode, the screen size (mm)."""
    return {"type": "hello", "url": url, "model": info.model, "firmware": info.firmware_version,
            "sensor": [info.camera_width, info.camera_height], "rate_hz": info.sample_rate_hz,
            "leds": info.led_count, "capabilities": [c.name for c in Capability if c in info.capabilities],
            "stream": stream, "screen": None if screen is None else [float(v) for v in screen.size_mm],
            "blink": blink}


def dumps(message: dict) -> str:
    """Compact JSON (NaN is never emitted: callers pass numbers through `number`)."""
    return json.dumps(message, separators=(",", ":"), allow_nan=False)
