"""The common interface of host gaze estimators, and angular-error helpers.

Samples are what a device streams per eye and fixation: the pupil centre (px), the glint centres
(px, one per LED, in the order of `TrackerGeometry.leds`) and a validity flag; image coordinates
follow OpenCV (origin at the top-left pixel centre, x right, y down).

An estimator's `calibrate(samples, targets_mm)` returns either a `Calibration` (which maps samples
to gaze on the screen, in screen mm, see `geometry.Screen`, and carries its fitted parameters) or a
`CalibrationFailure` naming why a fit was impossible (too few targets for the model's terms, a
rank-deficient design, no convergence). Malformed input (wrong shapes, NaN in valid samples)
raises ValueError. A failure is falsy, as in scikit-image's `EllipseModel.from_estimate`:

    result = estimator.calibrate(samples, targets)
    if not result:
        print(result.reason)
    gaze_mm = result.estimate(samples)
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

import numpy as np

#: Viewing distance (mm) of the published study's error form atan(distance on screen / 650 mm).
STUDY_VIEWING_DISTANCE_MM = 650.0


@dataclass(frozen=True, eq=False)
class EyeSamples:
    """Per-eye features, batched over leading dimensions `shape`.

    pupil_px (*shape, 2); glints_px (*shape, n_leds, 2); valid (*shape) bool. Entries of invalid
    samples may be NaN; valid samples must be finite.
    """

    pupil_px: np.ndarray
    glints_px: np.ndarray
    valid: np.ndarray | None = None

    def __post_init__(self) -> None:
        pupil = np.asarray(self.pupil_px, dtype=float)
        glints = np.asarray(self.glints_px, dtype=float)
        if pupil.ndim < 1 or pupil.shape[-1] != 2:
            raise ValueError(f"pupil_px must have shape (..., 2), got {pupil.shape}")
        if glints.shape[:-2] != pupil.shape[:-1] or glints.shape[-1:] != (2,) or glints.ndim < 2:
            raise ValueError(f"glints_px must have shape {(*pupil.shape[:-1], 'n_leds', 2)}, got {glints.shape}")
        valid = np.ones(pupil.shape[:-1], bool) if self.valid is None else np.asarray(self.valid)
        if valid.shape != pupil.shape[:-1] or valid.dtype != bool:
            raise ValueError(f"valid must be a bool array of shape {pupil.shape[:-1]}, got {valid.dtype} {valid.shape}")
        finite = np.isfinite(pupil).all(-1) & np.isfinite(glints).all((-2, -1))
        if np.any(valid & ~finite):
            raise ValueError("valid samples must have finite pupil and glint coordinates")
        object.__setattr__(self, "pupil_px", pupil)
        object.__setattr__(self, "glints_px", glints)
        object.__setattr__(self, "valid", valid)

    @property
    def shape(self) -> tuple[int, ...]:
        """Batch shape (without the coordinate and LED axes)."""
        return self.pupil_px.shape[:-1]

    @property
    def n_leds(self) -> int:
        """Number of glints per sample."""
        return int(self.glints_px.shape[-2])


@dataclass(frozen=True, eq=False)
class BinocularSamples:
    """Right- and left-eye samples of the same fixations (equal batch shapes and LED counts)."""

    right: EyeSamples
    left: EyeSamples

    def __post_init__(self) -> None:
        if self.right.shape != self.left.shape or self.right.n_leds != self.left.n_leds:
            raise ValueError("right and left samples must have equal shapes and LED counts")

    @property
    def shape(self) -> tuple[int, ...]:
        """Batch shape."""
        return self.right.shape

    @property
    def valid(self) -> np.ndarray:
        """Both eyes valid (*shape) bool."""
        return self.right.valid & self.left.valid


S = TypeVar("S", contravariant=True)


@dataclass(frozen=True)
class CalibrationFailure:
    """An explicit, falsy calibration failure: `method` could not fit, for `reason`."""

    method: str
    reason: str

    def __bool__(self) -> bool:
        return False


class Calibration(ABC, Generic[S]):
    """A calibrated estimator: maps samples to gaze on the screen (screen mm)."""

    @property
    @abstractmethod
    def params(self) -> Mapping[str, object]:
        """The fitted parameters (names and units documented by the estimator)."""

    @abstractmethod
    def estimate(self, samples: S) -> np.ndarray:
        """Point of gaze (*shape, 2) in screen mm; NaN where a sample is invalid or unusable."""

    def __bool__(self) -> bool:
        return True


class Estimator(Protocol[S]):
    """Anything that calibrates from samples at known targets (screen mm)."""

    def calibrate(self, samples: S, targets_mm: np.ndarray) -> Calibration[S] | CalibrationFailure:
        """Fit on `samples` (*shape) whose fixated targets are `targets_mm` (*shape, 2)."""
        ...


def check_targets(targets_mm: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """`targets_mm` as a finite float array of shape (*shape, 2); ValueError otherwise."""
    targets = np.asarray(targets_mm, dtype=float)
    if targets.shape != (*shape, 2):
        raise ValueError(f"targets_mm must have shape {(*shape, 2)}, got {targets.shape}")
    if not np.all(np.isfinite(targets)):
        raise ValueError("targets_mm must be finite")
    return targets


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (deg) between vectors a and b (..., 3): atan2(|a x b|, a.b), accurate at small angles."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def angular_error_deg(eye_positions: np.ndarray, estimates_world: np.ndarray, targets_world: np.ndarray) -> np.ndarray:
    """Gaze error (deg): the angle at the eye between eye -> estimate and eye -> target.

    All inputs are world points (..., 3) mm, broadcast together.
    """
    eye = np.asarray(eye_positions, float)
    return angle_between_deg(np.asarray(estimates_world, float) - eye, np.asarray(targets_world, float) - eye)


def on_screen_error_deg(
    estimates_mm: np.ndarray, targets_mm: np.ndarray, viewing_distance_mm: float = STUDY_VIEWING_DISTANCE_MM
) -> np.ndarray:
    """The published study's error form: atan(|estimate - target| / viewing distance), in degrees.

    estimates_mm, targets_mm: (..., 2) screen mm. Fischer et al. 2023 converted Guestrin &
    Eizenman's on-screen errors with a 650 mm viewing distance.
    """
    dist = np.linalg.norm(np.asarray(estimates_mm, float) - np.asarray(targets_mm, float), axis=-1)
    return np.degrees(np.arctan(dist / viewing_distance_mm))
