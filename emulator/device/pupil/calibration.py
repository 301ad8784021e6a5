"""Calibration as Pupil Capture runs it, with the host estimators of `eyehil.drivers.gaze` as the gazers.

Screen coordinates. Pupil's reference data and gaze `norm_pos` are normalised SCREEN coordinates (the
emulator's "world" is the screen): origin at the bottom-left corner as the subject sees the screen, x to the
subject's right, y up, (1, 1) at the top-right corner. The scene's screen coordinates
(`eyehil.emulator.scene.Screen.to_screen`) are mm from the screen centre, x toward world +x (the subject's LEFT),
y up; for a screen of W x H mm:

    x_mm = (0.5 - nx) W,   y_mm = (ny - 0.5) H;        nx = 0.5 - x_mm / W,   ny = 0.5 + y_mm / H.

Known answer (guestrin2006, 377 x 301 mm): norm (0, 1), the top-left corner as the subject sees it, is
(+188.5, +150.5) mm: the subject's left and up, as the STIMULUS message's top-left corner
(`eyehil.emulator.device.stimulus`).

A session collects targets and the device's samples. A target is a run of reference data at one norm_pos
(onset: its first timestamp, end: its last) or an ``eyehil.stimulus`` (end: the next target's onset, or
the stop). The samples of a target are paired with it by time: those in [onset + settle_s, end] (the
subject's saccadic latency and saccade come first), averaged per eye into one fixation, as a host does.

Gazers, chosen per scene (`fit`):

- two or more LEDs: Guestrin & Eizenman 2006 (`eyehil.drivers.gaze.guestrin`), one fit per tracked eye
  (``GazerGuestrin``); gaze of one eye alone, or the mean of both when both are valid;
- one LED, both eyes: Blignaut 2014 (`eyehil.drivers.gaze.blignaut`, binocular, LED 0), published model 3 with
  six targets or more, else model 2 (four or more), else model 1 (``GazerBlignaut``);
- one LED and one eye: no estimator of `eyehil.drivers.gaze` calibrates it without the eye's distance, so
  ``calibration.failed``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.drivers.gaze.base import BinocularSamples, Calibration, EyeSamples
from eyehil.drivers.gaze.blignaut import BlignautEstimator
from eyehil.drivers.gaze.geometry import Camera, Screen, TrackerGeometry
from eyehil.drivers.gaze.guestrin import GuestrinEstimator
from eyehil.emulator.scene import Scene
from eyehil.protocols.pupil import plain

MAX_SAMPLES = 2_000_000  # a session keeps at most this many exposures (the oldest go first)
MAX_TARGETS = 256  # targets per session (more are refused)


def norm_to_screen(size_mm: tuple[float, float], norm: np.ndarray) -> np.ndarray:
    """Scene screen mm (..., 2) of normalised screen positions (..., 2); see the module docstring."""
    n = np.asarray(norm, float)
    return np.stack([(0.5 - n[..., 0]) * size_mm[0], (n[..., 1] - 0.5) * size_mm[1]], axis=-1)


def screen_to_norm(size_mm: tuple[float, float], xy_mm: np.ndarray) -> np.ndarray:
    """Normalised screen positions (..., 2) of scene screen mm (..., 2)."""
    xy = np.asarray(xy_mm, float)
    return np.stack([0.5 - xy[..., 0] / size_mm[0], 0.5 + xy[..., 1] / size_mm[1]], axis=-1)


def host_geometry(scene: Scene) -> TrackerGeometry:
    """What Pupil Capture would know of the set-up: camera, LEDs and screen of `scene` (world = scene frame)."""
    cam = scene.camera
    camera = Camera(K=cam.matrix, R=cam.rotation, o=cam.position, image_size=cam.resolution_px)
    return TrackerGeometry(camera=camera, leds=scene.leds, screen=Screen(scene.screen.centre, scene.screen.size))


@dataclass
class Target:
    """A calibration target: scene screen mm, and when it was shown (Pupil time, s; end None = until the next)."""

    screen_mm: tuple[float, float]
    onset_s: float
    end_s: float | None


@dataclass(frozen=True)
class Fixations:
    """One averaged sample per usable target: targets (K, 2) mm, pupils (K, E, 2), glints (K, E, G, 2), valid (K, E)."""

    targets_mm: np.ndarray
    pupil: np.ndarray
    glints: np.ndarray
    valid: np.ndarray


class Session:
    """The targets and samples of one calibration (between should_start and should_stop)."""

    def __init__(self, settle_s: float) -> None:
        """Samples in the first `settle_s` after a target's onset are not used."""
        self.settle_s = settle_s
        self.targets: list[Target] = []
        self._blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._rows = 0

    def add_ref(self, screen_mm: tuple[float, float], t_s: float) -> bool | None:
        """A reference datum; True if it starts a new target (the subject must look there), None if refused
        (`MAX_TARGETS` reached)."""
        last = self.targets[-1] if self.targets else None
        if last is not None and np.allclose(last.screen_mm, screen_mm, atol=1e-6) and last.end_s is not None:
            last.end_s = max(last.end_s, t_s)
            return False
        if len(self.targets) >= MAX_TARGETS:
            return None
        self.targets.append(Target(screen_mm, t_s, t_s))
        return True

    def add_stimulus(self, screen_mm: tuple[float, float], t_s: float) -> bool:
        """A target shown until the next one (or the stop); False if refused (`MAX_TARGETS` reached)."""
        if len(self.targets) >= MAX_TARGETS:
            return False
        self.targets.append(Target(screen_mm, t_s, None))
        return True

    def add_samples(self, times_s: np.ndarray, pupil: np.ndarray, glints: np.ndarray, valid: np.ndarray) -> None:
        """Exposures at Pupil times (N,) s: full-sensor pupils (N, E, 2), glints (N, E, G, 2), validity (N, E)."""
        self._blocks.append((times_s, pupil, glints, valid))
        self._rows += len(times_s)
        while self._rows > MAX_SAMPLES and len(self._blocks) > 1:
            self._rows -= len(self._blocks.pop(0)[0])

    def fixations(self, stop_s: float) -> Fixations:
        """One fixation per target with valid samples in its window (see the module docstring)."""
        if not self._blocks:
            return _no_fixations((0, 2), (0, 0, 2))
        t, pupil, glints, valid = (np.concatenate(parts) for parts in zip(*self._blocks, strict=True))
        rows = []
        for i, target in enumerate(self.targets):
            end = target.end_s if target.end_s is not None else (
                self.targets[i + 1].onset_s if i + 1 < len(self.targets) else stop_s)
            use = ((t >= target.onset_s + self.settle_s) & (t <= end))[:, None] & valid  # (N, E)
            counts = use.sum(0)
            if counts.any():
                n = np.maximum(counts, 1)
                p = np.where(use[..., None], pupil, 0.0).sum(0) / n[:, None]
                g = np.where(use[..., None, None], glints, 0.0).sum(0) / n[:, None, None]
                rows.append((target.screen_mm, p, g, counts > 0))
        if not rows:
            return _no_fixations(pupil.shape[1:], glints.shape[1:])
        targets, p, g, v = (np.stack(a) for a in zip(*rows, strict=True))
        return Fixations(targets.astype(float), np.where(v[..., None], p, np.nan),
                         np.where(v[..., None, None], g, np.nan), v)


def _no_fixations(pupil_shape: tuple[int, ...], glint_shape: tuple[int, ...]) -> Fixations:
    return Fixations(np.empty((0, 2)), np.empty((0, *pupil_shape)), np.empty((0, *glint_shape)),
                     np.empty((0, pupil_shape[0]), bool))


@dataclass(frozen=True, eq=False)
class Gazer:
    """A fitted gazer: maps samples of the tracked eyes to gaze on the screen (scene screen mm)."""

    class_name: str
    calibrations: tuple[Calibration, ...]  # one per eye (Guestrin) or one binocular (Blignaut)
    eye_ids: tuple[int, ...]
    leds: int  # glints used per eye
    n_targets: int

    @property
    def params(self) -> dict:
        """msgpack-ready parameters for `calibration.result.v2`."""
        fits = {str(e): plain(c.params) for e, c in zip(self.eye_ids, self.calibrations, strict=False)}
        return {"eyes": fits if self.class_name == "GazerGuestrin" else {"01": plain(self.calibrations[0].params)},
                "n_targets": self.n_targets, "leds": self.leds}

    def map(self, pupil: np.ndarray, glints: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gaze (N, 2) screen mm (NaN where unusable) and which eyes were used (N, E), from samples as in
        `Session.add_samples` (glints of the first `leds` LEDs)."""
        if self.class_name == "GazerBlignaut":
            both = BinocularSamples(EyeSamples(pupil[:, 0], glints[:, 0], valid[:, 0]),
                                    EyeSamples(pupil[:, 1], glints[:, 1], valid[:, 1]))
            used = np.repeat(both.valid[:, None], 2, axis=1)
            return self.calibrations[0].estimate(both), used
        per_eye = np.stack([c.estimate(EyeSamples(pupil[:, e], glints[:, e], valid[:, e]))
                            for e, c in enumerate(self.calibrations)], axis=1)  # (N, E, 2)
        used = valid & np.isfinite(per_eye).all(-1)
        with np.errstate(invalid="ignore"):
            gaze = np.nansum(np.where(used[..., None], per_eye, 0.0), 1) / used.sum(1)[:, None]
        return gaze, used


def _blignaut_model(n_targets: int) -> int:
    return 3 if n_targets >= 6 else 2 if n_targets >= 4 else 1


def fit(fixations: Fixations, scene: Scene, eye_ids: tuple[int, ...]) -> Gazer | str:
    """The gazer for `scene` fitted on `fixations`, or why it cannot be (see the module docstring)."""
    leds = len(scene.leds)
    if leds == 1 and len(eye_ids) == 1:
        return "one LED and one eye: no gazer (Blignaut needs both eyes, Guestrin two LEDs)"
    f = fixations
    if len(f.targets_mm) == 0:
        return "no calibration target with pupil data after the settling time"
    if leds == 1:
        usable = int(f.valid.all(-1).sum())
        est = BlignautEstimator.from_model(_blignaut_model(usable))
        result = est.calibrate(BinocularSamples(*(EyeSamples(f.pupil[:, e], f.glints[:, e, :1], f.valid[:, e])
                                                  for e in range(2))), f.targets_mm)
        return Gazer("GazerBlignaut", (result,), eye_ids, 1, usable) if result else result.reason
    geometry = host_geometry(scene)
    fits = []
    for e, eye_id in enumerate(eye_ids):
        est = GuestrinEstimator(geometry, eye="right" if eye_id == 0 else "left")
        result = est.calibrate(EyeSamples(f.pupil[:, e], f.glints[:, e], f.valid[:, e]), f.targets_mm)
        if not result:
            return f"{'right' if eye_id == 0 else 'left'} eye: {result.reason}"
        fits.append(result)
    return Gazer("GazerGuestrin", tuple(fits), eye_ids, leds, int(f.valid.any(-1).sum()))
