"""Open Gaze data values of the device's exposures, vectorised over exposures x eyes.

Units and frames (docs/opengaze.md):

- points of gaze (``[LRB]POGX/Y``, ``FPOGX/Y``): fractions of the screen, origin at the top-left corner as
  the subject sees the screen, x to the subject's right, y DOWN ((1, 1) bottom-right). From scene screen mm
  (`eyehil.emulator.scene`: x toward world +x = the subject's left, y up) of a W x H mm screen:
  ``gx = 0.5 - x_mm / W``, ``gy = 0.5 - y_mm / H``;
- pupil centre (``[LR]PCX/Y``): fractions of the camera image (full-sensor px / (w, h));
  ``[LR]PD`` the pupil ellipse's major axis in px; ``[LR]PS`` the distance scale (1 at the calibration
  distance; the head is fixed, so 1 while valid);
- eye position (``[LR]EYEX/Y/Z``): the eye's unrotated corneal apex relative to the camera's centre of
  projection, in the scene frame's axes (x toward the subject's left, y up, z from the subject toward the
  screen), metres; ``[LR]PUPILD`` the anatomical pupil's diameter in metres, ``[LR]PMM`` in mm.

Eyes: Open Gaze's L is the subject's left eye, R the right eye; an eye the camera does not track has
validity 0 and zeros.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.camera import Exposures
from eyehil.emulator.device.pupil.calibration import Gazer
from eyehil.emulator.device.pupil.datums import sample_arrays
from eyehil.emulator.scene import Scene
from eyehil.protocols.enums import PupilFlags

SIDES = ("left", "right")  # Open Gaze's L, R


def screen_fraction(size_mm: tuple[float, float], xy_mm: np.ndarray) -> np.ndarray:
    """Open Gaze screen fractions (..., 2) of scene screen mm (..., 2); see the module docstring."""
    xy = np.asarray(xy_mm, float)
    return np.stack([0.5 - xy[..., 0] / size_mm[0], 0.5 - xy[..., 1] / size_mm[1]], axis=-1)


def fraction_to_screen(size_mm: tuple[float, float], g: np.ndarray) -> np.ndarray:
    """Scene screen mm (..., 2) of Open Gaze screen fractions (..., 2)."""
    g = np.asarray(g, float)
    return np.stack([(0.5 - g[..., 0]) * size_mm[0], (0.5 - g[..., 1]) * size_mm[1]], axis=-1)


@dataclass(frozen=True)
class EyeGeometry:
    """What does not change while the head is still: eye positions (2, 3) m (L, R; NaN if untracked) and the
    anatomical pupil diameter (mm)."""

    position_m: np.ndarray
    pupil_mm: float

    @classmethod
    def of(cls, scene: Scene, head_rotation: np.ndarray, head_translation: np.ndarray, pupil_radius_mm: float
           ) -> EyeGeometry:
        pos = np.full((2, 3), np.nan)
        for i, side in enumerate(SIDES):
            if side in scene.sides:
                world = head_rotation @ scene.apex(side) + head_translation
                pos[i] = (world - scene.camera.position) / 1000.0
        return cls(pos, 2.0 * pupil_radius_mm)


class CachedGazer:
    """A gazer's per-eye mapping with a bounded cache keyed by the exact sample (pupil and glints of the eyes it
    maps together): one estimator call costs tens of milliseconds whatever the batch, and a fixating eye
    without jitter shows the same features exposure after exposure, so only new samples are estimated, in
    one vectorised call per eye (Blignaut: per pair of eyes)."""

    MAX_ENTRIES = 4096

    def __init__(self, gazer: Gazer) -> None:
        self.gazer = gazer
        self.leds = gazer.leds
        self._cache: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self.hits = self.misses = 0

    def map_eyes(self, pupil: np.ndarray, glints: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As `Gazer.map_eyes`: gaze (N, E, 2) screen mm and validity (N, E)."""
        n = len(pupil)
        rows = np.concatenate([pupil.reshape(n, -1), glints.reshape(n, -1), valid.reshape(n, -1)], axis=1)
        keys = [r.tobytes() for r in np.ascontiguousarray(rows)]
        missing = [i for i, k in enumerate(dict.fromkeys(keys)) if k not in self._cache]
        if missing:
            first = {k: i for i, k in reversed(list(enumerate(keys)))}
            todo = [first[k] for k in dict.fromkeys(keys) if k not in self._cache]
            gaze, used = self.gazer.map_eyes(pupil[todo], glints[todo], valid[todo])
            for j, i in enumerate(todo):
                self._cache[keys[i]] = (gaze[j], used[j])
            self.misses += len(todo)
            while len(self._cache) > self.MAX_ENTRIES:
                self._cache.popitem(last=False)
        self.hits += n - len(missing)
        out = [self._cache[k] for k in keys]
        return np.stack([g for g, _ in out]), np.stack([u for _, u in out])


@dataclass(frozen=True)
class Values:
    """Per exposure (N) and Open Gaze eye (2: L, R): gaze fractions (N, 2, 2) and validity (N, 2), best
    gaze (N, 2) and validity (N,), pupil centre fractions (N, 2, 2), diameter px (N, 2), pupil validity
    (N, 2), blink (N,), device times (N,) us."""

    pog: np.ndarray
    pog_valid: np.ndarray
    best: np.ndarray
    best_valid: np.ndarray
    pupil: np.ndarray
    diameter_px: np.ndarray
    pupil_valid: np.ndarray
    blink: np.ndarray
    time_us: np.ndarray


def exposure_values(exp: Exposures, scene: Scene, gazer: Gazer | CachedGazer | None) -> Values:
    """The values of `exp` (tracked eyes in the scene's `sides` order), gaze from `gazer` (None: invalid)."""
    n = len(exp)
    col = [scene.sides.index(s) if s in scene.sides else None for s in SIDES]
    b = exp.batch
    sensor = np.asarray(scene.camera.resolution_px, float)
    found = (b.flags & PupilFlags.DETECTED) != 0  # (N, E)
    pupil, diameter, pvalid = np.zeros((n, 2, 2)), np.zeros((n, 2)), np.zeros((n, 2), bool)
    pog, gvalid = np.zeros((n, 2, 2)), np.zeros((n, 2), bool)
    if gazer is not None:
        p, g, v = sample_arrays(exp, gazer.leds)
        mm, used = gazer.map_eyes(p, g, v)
        frac = screen_fraction(scene.screen.size, mm)
    for i, c in enumerate(col):
        if c is None:
            continue
        pvalid[:, i] = found[:, c]
        pupil[:, i] = np.where(found[:, c, None], b.centre[:, c] / sensor, 0.0)
        diameter[:, i] = np.where(found[:, c], b.axes[:, c].max(-1), 0.0)
        if gazer is not None:
            gvalid[:, i] = used[:, c]
            pog[:, i] = np.where(used[:, c, None], frac[:, c], 0.0)
    count = gvalid.sum(1)
    best = np.where(count[:, None] > 0, pog.sum(1) / np.maximum(count, 1)[:, None], 0.0)
    return Values(pog, gvalid, best, count > 0, pupil, diameter, pvalid, np.asarray(exp.blink, bool),
                  np.asarray(exp.time_us, np.int64))
