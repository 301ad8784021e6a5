"""Gaze datums and the per-exposure block for the LSL outlet, mapped in small batches.

The host estimators cost about 2 ms per call whatever the number of samples, so the facade maps the exposures
it has published in batches: when the oldest waiting exposure is `BATCH_S` old (device time) or
`BATCH_MAX` wait. Gaze datums therefore trail their pupil datums by up to `BATCH_S`.

Gaze datum (`eyehil.protocols.pupil.gaze_datum`): topic ``gaze.2d.<ids>.`` with the Pupil ids of the eyes used
(``gaze.2d.01.`` binocular, ``gaze.2d.0.`` right eye only, ``gaze.2d.1.`` left eye only), `norm_pos` on the
screen (`zmq_calibration`), confidence the mean of the pupils used, the exposure's timestamp, and
`base_data`, the pupil datums used. Exposures that no eye maps give no gaze datum.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from eyehil.emulator.device.camera import Exposures
from eyehil.emulator.device.pupil.calibration import Gazer, screen_to_norm
from eyehil.emulator.device.pupil.datums import EyeWindow, PupilTime, sample_arrays
from eyehil.protocols.enums import GlintFlags, PupilFlags
from eyehil.protocols.pupil import gaze_datum

BATCH_S = 0.01
BATCH_MAX = 64


@dataclass(frozen=True)
class Block:
    """Exposures mapped together, for the LSL outlet: device times (N,) us; per eye, in eye-image px (NaN
    where not detected): pupil centre (N, E, 2), diameter (N, E), confidence (N, E), glints (N, E, G, 2); gaze
    (N, 2) normalised screen (NaN without a gazer or a usable eye) and its confidence (N,)."""

    time_us: np.ndarray
    pupil: np.ndarray
    diameter: np.ndarray
    confidence: np.ndarray
    glints: np.ndarray
    gaze: np.ndarray
    gaze_confidence: np.ndarray


def _eye_image(exps: list[Exposures], windows: list[EyeWindow]) -> dict[str, np.ndarray]:
    """Pupil, diameter, confidence and glints of `exps` in eye-image px (NaN where not found)."""
    b = [e.batch for e in exps]
    origin = np.stack([w.origin for w in windows])  # (E, 2)
    found = np.concatenate([(x.flags & PupilFlags.DETECTED) != 0 for x in b])
    glint_ok = np.concatenate([(x.glint_flags & GlintFlags.VALID) != 0 for x in b])
    centre = np.concatenate([x.centre for x in b]) - origin
    glints = np.concatenate([x.glint_xy for x in b]) - origin[:, None, :]
    return {"pupil": np.where(found[..., None], centre, np.nan),
            "diameter": np.where(found, np.concatenate([x.axes for x in b]).max(-1), np.nan),
            "confidence": np.concatenate([x.confidence for x in b]),
            "glints": np.where(glint_ok[..., None], glints, np.nan)}


class GazeStream:
    """Exposures waiting to be mapped, with their pupil datums; see the module docstring."""

    def __init__(self, windows: list[EyeWindow], time: PupilTime, screen_mm: tuple[float, float]) -> None:
        """`windows`: the eye images (eyes in the exposures' order); `screen_mm`: the screen's size (W, H)."""
        self.windows, self.time, self.screen_mm = windows, time, screen_mm
        self._exps: list[Exposures] = []
        self._datums: list[list[dict[str, Any]]] = []  # per exposure, the pupil datum of each eye

    def add(self, exp: Exposures, pupil_datums: list[list[dict[str, Any]]]) -> None:
        """Exposures just published and their pupil datums (one list of E datums per exposure)."""
        self._exps.append(exp)
        self._datums.extend(pupil_datums)

    def due(self, now_us: int) -> bool:
        """True when the waiting exposures should be mapped now."""
        return bool(self._exps) and (now_us - int(self._exps[0].time_us[0]) >= BATCH_S * 1e6
                                     or len(self._datums) >= BATCH_MAX)

    def flush(self, gazer: Gazer | None) -> tuple[list[dict[str, Any]], Block | None]:
        """Map the waiting exposures: (gaze datums, the block for the LSL outlet)."""
        if not self._exps:
            return [], None
        exps, datums, self._exps, self._datums = self._exps, self._datums, [], []
        t_us = np.concatenate([e.time_us for e in exps])
        n = len(t_us)
        gaze, used = np.full((n, 2), np.nan), np.zeros((n, len(self.windows)), bool)
        if gazer is not None:
            pupil, glints, valid = (np.concatenate(a) for a in zip(*(sample_arrays(e, gazer.leds) for e in exps),
                                                                   strict=True))
            mm, used = gazer.map(pupil, glints, valid)
            gaze = screen_to_norm(self.screen_mm, mm)
        eye = _eye_image(exps, self.windows)
        ok = np.isfinite(gaze).all(-1) & used.any(-1)
        with np.errstate(invalid="ignore"):
            conf = np.where(ok, (eye["confidence"] * used).sum(-1) / used.sum(-1), 0.0)
        out = []
        for i in np.flatnonzero(ok):
            eyes = np.flatnonzero(used[i])
            out.append(gaze_datum([self.windows[e].eye_id for e in eyes], float(self.time.of_us(int(t_us[i]))),
                                  gaze[i], float(conf[i]), [datums[i][e] for e in eyes]))
        block = Block(t_us, eye["pupil"], eye["diameter"], eye["confidence"], eye["glints"],
                      np.where(ok[:, None], gaze, np.nan), conf)
        return out, block
