"""The page's eye panel drawn with OpenCV (for `--record-video`): the camera image or a rendering of the features,
with the pupil ellipse, its centre, the glints and their LED labels.

Pure numpy/OpenCV, no I/O. Input records are `eyehil.drivers.view.payload.eye_record` dicts (full-sensor px, OpenCV
convention; ellipse axes are full lengths, angle in degrees from image +x toward +y); `origin` is the sensor
pixel at the panel's top-left. Colours are those of `static/view.js`.
"""

from __future__ import annotations

import cv2
import numpy as np

PANEL = (320, 240)  # width, height px
PUPIL, GLINT, TEXT = (51, 255, 51), (51, 204, 255), (204, 204, 204)  # BGR
SHIFT = 4  # fixed-point bits for sub-pixel drawing


def _fixed(x: float, y: float) -> tuple[int, int]:
    return round(x * (1 << SHIFT)), round(y * (1 << SHIFT))


def features_panel(record: dict | None, size: tuple[int, int] = PANEL) -> tuple[np.ndarray, tuple[int, int]]:
    """A grey panel with the pupil (dark ellipse) and glints (white) of `record`, centred on the pupil; and its
    origin (sensor px of the top-left)."""
    w, h = size
    panel = np.full((h, w, 3), 138, np.uint8)
    if not record or not record.get("detected") or record.get("x") is None:
        return panel, (0, 0)
    origin = (round(record["x"] - w / 2), round(record["y"] - h / 2))
    centre = _fixed(record["x"] - origin[0], record["y"] - origin[1])
    axes = _fixed(record["a"] / 2, record["b"] / 2)
    cv2.circle(panel, centre, round(max(record["a"], 8) * 1.9 * (1 << SHIFT)), (85, 85, 85), -1, cv2.LINE_AA, SHIFT)
    cv2.ellipse(panel, centre, axes, record["angle"] or 0.0, 0, 360, (20, 20, 20), -1, cv2.LINE_AA, SHIFT)
    for g in record["glints"]:
        cv2.circle(panel, _fixed(g["x"] - origin[0], g["y"] - origin[1]), 40, (255, 255, 255), -1, cv2.LINE_AA, SHIFT)
    return panel, origin


def image_panel(pixels: np.ndarray) -> np.ndarray:
    """A camera image (uint8 or uint16 MONO) as BGR."""
    if pixels.dtype != np.uint8:
        pixels = (pixels >> 8).astype(np.uint8)
    return cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)


def draw_overlay(panel: np.ndarray, record: dict | None, origin: tuple[int, int]) -> np.ndarray:
    """Draw `record` over `panel` (in place; returned)."""
    if not record:
        return panel
    label = "blink" if record.get("blink") else f"confidence {record['confidence'] or 0:.2f}"
    panel[:19, :112] = (panel[:19, :112] * 0.4).astype(np.uint8)  # the page's dark label box
    cv2.putText(panel, label, (6, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, TEXT, 1, cv2.LINE_AA)
    if record.get("detected") and record.get("x") is not None:
        x, y = record["x"] - origin[0], record["y"] - origin[1]
        cv2.ellipse(panel, _fixed(x, y), _fixed(record["a"] / 2, record["b"] / 2), record["angle"] or 0.0, 0, 360,
                    PUPIL, 1, cv2.LINE_AA, SHIFT)
        cv2.drawMarker(panel, (round(x), round(y)), PUPIL, cv2.MARKER_CROSS, 8, 1)
    for g in record["glints"]:
        x, y = g["x"] - origin[0], g["y"] - origin[1]
        cv2.circle(panel, _fixed(x, y), 4 << SHIFT, GLINT, 1, cv2.LINE_AA, SHIFT)
        label_at = (round(x) + 6, round(y) - 8 - 11 * g["led"])
        cv2.putText(panel, f"LED {g['led']}", label_at, cv2.FONT_HERSHEY_SIMPLEX, 0.35, GLINT, 1, cv2.LINE_AA)
    return panel


def fit(panel: np.ndarray, size: tuple[int, int] = PANEL) -> np.ndarray:
    """`panel` cropped or padded (black) to `size` (width, height), top-left anchored."""
    w, h = size
    out = np.zeros((h, w, 3), np.uint8)
    ph, pw = min(h, panel.shape[0]), min(w, panel.shape[1])
    out[:ph, :pw] = panel[:ph, :pw]
    return out
