"""The Gaze stream's channels and rows (pure): which values a sample carries, in which order, with which metadata.

Channel metadata follow the XDF gaze meta-data conventions, as Pupil Capture's LSL relay does:
``desc/channels/channel`` with ``label``, ``eye`` (right, left, both), ``type``, ``unit`` and
``coordinate_system``:

| label | eye | type | unit | coordinate system | value |
|---|---|---|---|---|---|
| confidence | both | Confidence | normalized | | gaze confidence (0 without a calibration) |
| norm_pos_x, norm_pos_y | both | ScreenX, ScreenY | normalized | screen | gaze on the screen, origin bottom-left |
| pupil{i}_x, pupil{i}_y | right / left | PupilX, PupilY | pixels | eye{i} | pupil centre in the eye image |
| diameter{i}_2d | right / left | Diameter | pixels | eye{i} | major axis of the pupil ellipse |
| confidence{i} | right / left | Confidence | normalized | eye{i} | pupil confidence |
| glint{i}_{l}_x, glint{i}_{l}_y | right / left | ReflexX, ReflexY | pixels | eye{i} | glint of LED l |

for each tracked eye i (Pupil's ids: 0 right, 1 left) and LED l. Eye-image pixels and the screen's
normalised coordinates are those of the ZeroMQ datums (`pupil.datums`, `pupil.calibration`).

With the layout "pupil_relay" the stream is laid out as Pupil Capture's LSL relay (pupil-labs
`pupil_capture_lsl_relay`, outlet v2): 22 channels: confidence, norm_pos_x/y, gaze_point_3d_x/y/z (mm; here
the gaze point on the screen in the scene frame), then per eye 0 and 1 eye_center{i}_3d_x/y/z (mm, scene frame:
the 3-D eye model's sphere centre, `pupil.eye3d`) and gaze_normal{i}_x/y/z (unit, from that centre to the gaze
point), NaN without gaze or where the eye's pupil was not detected, and diameter{i}_2d (px), diameter{i}_3d (mm;
the anatomical pupil, NaN when not detected).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from eyehil.emulator.device.pupil.calibration import norm_to_screen
from eyehil.emulator.device.pupil.gaze import Block


@dataclass(frozen=True)
class Channel:
    """One channel's metadata."""

    label: str
    eye: str
    type: str
    unit: str
    coordinate_system: str = ""


def gaze_channels(eye_ids: tuple[int, ...], n_leds: int) -> list[Channel]:
    """The channels of the stream, in sample order (see the module docstring)."""
    out = [Channel("confidence", "both", "Confidence", "normalized"),
           Channel("norm_pos_x", "both", "ScreenX", "normalized", "screen"),
           Channel("norm_pos_y", "both", "ScreenY", "normalized", "screen")]
    for i in eye_ids:
        eye, system = ("right", "left")[i], f"eye{i}"
        out += [Channel(f"pupil{i}_x", eye, "PupilX", "pixels", system),
                Channel(f"pupil{i}_y", eye, "PupilY", "pixels", system),
                Channel(f"diameter{i}_2d", eye, "Diameter", "pixels", system),
                Channel(f"confidence{i}", eye, "Confidence", "normalized", system)]
        for led in range(n_leds):
            out += [Channel(f"glint{i}_{led}_x", eye, "ReflexX", "pixels", system),
                    Channel(f"glint{i}_{led}_y", eye, "ReflexY", "pixels", system)]
    return out


def relay_channels() -> list[Channel]:
    """Pupil Capture's LSL relay gaze channels (see the module docstring), in sample order."""
    out = [Channel("confidence", "both", "Confidence", "normalized"),
           *(Channel(f"norm_pos_{a}", "both", f"Screen{a.upper()}", "normalized", "world") for a in "xy"),
           *(Channel(f"gaze_point_3d_{a}", "both", f"Direction{a.upper()}", "mm", "world") for a in "xyz")]
    for kind, label in (("Position", "eye_center{}_3d_{}"), ("Position", "gaze_normal{}_{}")):
        out += [Channel(label.format(i, a), ("right", "left")[i], kind + a.upper(), "mm", "world")
                for i in range(2) for a in "xyz"]
    out += [Channel(f"diameter{i}_2d", ("right", "left")[i], "Diameter", "pixels", f"eye{i}") for i in range(2)]
    out += [Channel(f"diameter{i}_3d", ("right", "left")[i], "Diameter", "mm", f"eye{i}") for i in range(2)]
    return out


def relay_rows(block: Block, eye_ids: tuple[int, ...], screen_centre: np.ndarray, screen_mm: tuple[float, float],
               pupil_mm: float, eye_centres: np.ndarray | None = None) -> np.ndarray:
    """Samples (N, 22) of a mapped block in `relay_channels` order; `eye_centres` (E, 3) scene mm, the 3-D eye
    model's sphere centres of the eyes in `eye_ids` order (`pupil.eye3d`), fill eye_center{i}_3d and
    gaze_normal{i} (unit, from the eye centre to the gaze point, as in ``gaze.3d`` datums) where the gaze is
    known and the eye's pupil was detected."""
    n = len(block.time_us)
    out = np.full((n, 22), np.nan)
    out[:, 0], out[:, 1:3] = block.gaze_confidence, block.gaze
    point = np.asarray(screen_centre, float) + np.concatenate([norm_to_screen(screen_mm, block.gaze),
                                                               np.zeros((n, 1))], axis=1)
    out[:, 3:6] = point
    for e, eye_id in enumerate(eye_ids):
        out[:, 18 + eye_id] = block.diameter[:, e]
        out[:, 20 + eye_id] = np.where(np.isfinite(block.diameter[:, e]), pupil_mm, np.nan)
        if eye_centres is not None:
            ok = np.isfinite(point).all(axis=1) & np.isfinite(block.diameter[:, e])
            towards = point[ok] - eye_centres[e]
            out[ok, 6 + 3 * eye_id:9 + 3 * eye_id] = eye_centres[e]
            out[ok, 12 + 3 * eye_id:15 + 3 * eye_id] = towards / np.linalg.norm(towards, axis=1, keepdims=True)
    return out


def block_rows(block: Block) -> np.ndarray:
    """Samples (N, channels) of a mapped block, in `gaze_channels` order."""
    n, e = block.confidence.shape
    columns = [block.gaze_confidence[:, None], block.gaze]
    for i in range(e):
        columns += [block.pupil[:, i], block.diameter[:, i, None], block.confidence[:, i, None],
                    block.glints[:, i].reshape(n, -1)]
    return np.concatenate(columns, axis=1).astype(np.float64)



def metadata(channels: list[Channel]) -> list[dict[str, str]]:
    """The channels' non-empty metadata fields, as the stream's desc/channels/channel nodes."""
    return [{k: v for k, v in asdict(ch).items() if v} for ch in channels]
