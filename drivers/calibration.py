"""Calibrate gaze through the device: show targets, collect fixations, fit, validate, then map samples to gaze.

For each target the host shows it (on the emulator: the STIMULUS side channel, `Tracker.stimulus`),
discards the samples of the first `settle_s` after the device acknowledged it (the subject's latency
and saccade), and averages the usable samples of the next `collect_s` (device time) into one fixation.
Calibration targets come first, then validation targets. The samples come either from the device's
FEATURES (`frames=False`) or, in frames-only mode (`frames=True`), from its camera images: the host
detects pupil and glints itself (`eyehil.drivers.frames.FrameReader`, LEDs matched with the geometry's). Methods:

- ``guestrin``: Guestrin & Eizenman 2006, model-based (`eyehil.drivers.gaze.guestrin`), one eye, the LEDs of
  the geometry file (two);
- ``blignaut``: Blignaut 2014 interpolation (`eyehil.drivers.gaze.blignaut`), both eyes, LED 0.

Targets and estimates are in SCREEN mm of `eyehil.drivers.gaze.geometry` (from the screen centre along world
+x = the subject's left, and +y = up). The STIMULUS message wants mm from the top-left corner, x to the
subject's right, y down: `screen_to_stimulus` is the one conversion (it assumes the default screen axes).
Validation error: the angle at the world origin (the subject's reference eye position, midway between
the eyes) between the directions to the estimate and to the target, degrees.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from eyehil.drivers.client import Tracker
from eyehil.drivers.errors import CalibrationError
from eyehil.drivers.features import binocular_samples, eye_samples, fixation_mean
from eyehil.drivers.frames import FrameReader, reader_for
from eyehil.drivers.gaze.base import BinocularSamples, Calibration, EyeSamples, angular_error_deg
from eyehil.drivers.gaze.blignaut import BlignautEstimator
from eyehil.drivers.gaze.geometry import Screen, TrackerGeometry
from eyehil.drivers.gaze.guestrin import GuestrinEstimator
from eyehil.drivers.wire import Sample
from eyehil.protocols.enums import Capability, Eye, EyeSelect, StreamSelect

METHODS = ("guestrin", "blignaut")


def grid(screen: Screen, columns: int, rows: int, fraction: float = 1.0) -> np.ndarray:
    """Targets (rows * columns, 2) screen mm spanning `fraction` of the screen, row by row from the top."""
    return screen.grid(columns, rows).reshape(-1, 2) * fraction


def screen_to_stimulus(screen: Screen, xy_mm: np.ndarray) -> np.ndarray:
    """STIMULUS coordinates (..., 2) (mm from the top-left corner, x right, y down as the subject sees the
    screen) of screen coordinates (..., 2) (mm from the centre, x toward the subject's left, y up)."""
    width, height = screen.size_mm
    xy = np.asarray(xy_mm, float)
    return np.stack([width / 2 - xy[..., 0], height / 2 - xy[..., 1]], axis=-1)


def validation_errors_deg(geometry: TrackerGeometry, estimates_mm: np.ndarray, targets_mm: np.ndarray) -> np.ndarray:
    """Angle (deg) at the world origin between estimate and target, both screen mm (..., 2)."""
    to_world = geometry.screen.to_world
    return angular_error_deg(np.zeros(3), to_world(estimates_mm), to_world(targets_mm))


@dataclass(frozen=True)
class Plan:
    """Targets (screen mm) and timing (device seconds)."""

    calibration_mm: np.ndarray
    validation_mm: np.ndarray
    settle_s: float = 0.5
    collect_s: float = 0.2

    @classmethod
    def default(cls, screen: Screen, **timing: float) -> Plan:
        """3 x 3 over the whole screen (corners included); validation on the 2 x 2 between them."""
        return cls(grid(screen, 3, 3), grid(screen, 2, 2, 0.5), **timing)


@dataclass(frozen=True)
class Result:
    """A calibration and its validation: errors (V,) deg, estimates (V, 2) screen mm, fixations used."""

    method: str
    calibration: Calibration
    plan: Plan
    estimates_mm: np.ndarray
    errors_deg: np.ndarray
    fixations: list[list[Sample]]

    @property
    def mean_error_deg(self) -> float:
        return float(np.nanmean(self.errors_deg))


def collect_fixation(tracker: Tracker, target_id: int, xy_mm: np.ndarray, screen: Screen, plan: Plan,
                     reader: Tracker | FrameReader | None = None) -> list[Sample]:
    """Show one target; return the samples (from `reader`, default the tracker) of its collection window."""
    x, y = screen_to_stimulus(screen, xy_mm)
    onset = tracker.stimulus(target_id, float(x), float(y))
    start, end = onset + round(plan.settle_s * 1e6), onset + round((plan.settle_s + plan.collect_s) * 1e6)
    if isinstance(reader, FrameReader):
        reader.detect_from_us = start  # the samples before are discarded: no need to detect them
    window: list[Sample] = []
    for sample in (reader or tracker).samples():
        if sample.device_us >= end:
            return window
        if sample.device_us >= start:
            window.append(sample)
    return window


def _stack(fixations: list[EyeSamples]) -> EyeSamples:
    return EyeSamples(np.stack([f.pupil_px for f in fixations]), np.stack([f.glints_px for f in fixations]),
                      np.stack([f.valid for f in fixations]))


def fixation_samples(fixations: list[list[Sample]], method: str, eye: Eye, n_leds: int
                     ) -> EyeSamples | BinocularSamples:
    """One averaged sample per fixation (K,): one eye for guestrin, both for blignaut."""
    if method == "guestrin":
        return _stack([fixation_mean(f, eye, n_leds) for f in fixations])
    return BinocularSamples(*(_stack([fixation_mean(f, e, n_leds) for f in fixations]) for e in (Eye.RIGHT, Eye.LEFT)))


def _subset(samples: EyeSamples | BinocularSamples, index: slice) -> EyeSamples | BinocularSamples:
    if isinstance(samples, BinocularSamples):
        return BinocularSamples(_subset(samples.right, index), _subset(samples.left, index))
    return EyeSamples(samples.pupil_px[index], samples.glints_px[index], samples.valid[index])


def estimator_for(method: str, geometry: TrackerGeometry, eye: Eye, model: int):
    """The estimator of `method` (guestrin: the `eye`; blignaut: published model `model`)."""
    if method == "guestrin":
        return GuestrinEstimator(geometry, eye="right" if eye == Eye.RIGHT else "left")
    if method == "blignaut":
        return BlignautEstimator.from_model(model)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def configure_for(tracker: Tracker, method: str, geometry: TrackerGeometry, eye: Eye, rate_hz: int | None,
                  frames: bool = False) -> int:
    """CONFIGURE the stream a method needs (guestrin: the geometry's LEDs; blignaut: LED 0, both eyes), FEATURES
    or, with `frames`, FRAMES only; return the number of glints per eye."""
    info = tracker.info
    if frames and Capability.FRAMES not in info.capabilities:
        raise CalibrationError("frames-only calibration needs a device that streams frames")
    if method == "blignaut" and Capability.BINOCULAR not in info.capabilities:
        raise CalibrationError("blignaut needs both eyes: the device is not binocular")
    if method == "guestrin" and geometry.n_leds > info.led_count:
        raise CalibrationError(f"the geometry has {geometry.n_leds} LEDs, the device {info.led_count}")
    leds = geometry.n_leds if method == "guestrin" else 1
    eyes = EyeSelect.BOTH if method == "blignaut" else EyeSelect(1 << eye)
    stream = StreamSelect.FRAMES if frames else StreamSelect.FEATURES
    tracker.configure(leds=leds, rate_hz=rate_hz, eyes=eyes, stream=stream)
    return leds


def check_geometry(geometry: TrackerGeometry, info) -> None:
    """Refuse a geometry file that cannot be this device's (another scene's camera or LEDs): CalibrationError
    naming both. `info` is the device's DEVICE_INFO (None: nothing to compare)."""
    if info is None:
        return
    width, height = geometry.camera.image_size
    if (width, height) != (info.camera_width, info.camera_height) or geometry.n_leds > info.led_count:
        raise CalibrationError(
            f"the geometry file describes a {width} x {height} px camera with {geometry.n_leds} LED(s), but the "
            f"device has a {info.camera_width} x {info.camera_height} px camera with {info.led_count} LED(s): "
            f"is it the geometry of another tracker or scene?")


def calibrate(tracker: Tracker, geometry: TrackerGeometry, method: str, plan: Plan | None = None, *,
              eye: Eye = Eye.RIGHT, model: int = 3, rate_hz: int | None = None, frames: bool = False,
              progress: Callable[[int, int], None] | None = None) -> Result:
    """Configure, stream, run `plan`'s targets, fit on the calibration ones, validate on the others; stop.
    With `frames`, the device streams images only and the host detects the features (frames-only mode).
    `progress(done, total)` is told after each target."""
    check_geometry(geometry, tracker.info)
    plan = plan or Plan.default(geometry.screen)
    estimator = estimator_for(method, geometry, eye, model)
    n_leds = configure_for(tracker, method, geometry, eye, rate_hz, frames)
    targets = np.concatenate([plan.calibration_mm, plan.validation_mm])
    reader = reader_for(tracker, frames, geometry.leds[:, :2])
    tracker.start()
    try:
        fixations = []
        for i, xy in enumerate(targets):
            fixations.append(collect_fixation(tracker, i, xy, geometry.screen, plan, reader))
            if progress is not None:
                progress(i + 1, len(targets))
    finally:
        tracker.stop()
    samples = fixation_samples(fixations, method, eye, n_leds)
    k = len(plan.calibration_mm)
    fit = estimator.calibrate(_subset(samples, slice(0, k)), plan.calibration_mm)
    if not fit:
        raise CalibrationError(f"{method}: {fit.reason}")
    estimates = fit.estimate(_subset(samples, slice(k, None)))
    errors = validation_errors_deg(geometry, estimates, plan.validation_mm)
    return Result(method, fit, plan, estimates, errors, fixations)


def gaze(tracker: Tracker, result: Result, eye: Eye = Eye.RIGHT, count: int | None = None,
         reader: FrameReader | None = None) -> Iterator[tuple[Sample, np.ndarray]]:
    """Stream (sample, gaze (2,) screen mm; NaN when unusable) with the calibration of `result` (call start first);
    samples from `reader` (frames-only mode) or the tracker's FEATURES."""
    for sample in (reader or tracker).samples(count=count):
        one = [sample]
        samples = eye_samples(one, eye) if result.method == "guestrin" else binocular_samples(one)
        yield sample, result.calibration.estimate(samples)[0]
