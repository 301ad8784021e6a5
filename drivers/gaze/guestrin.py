"""Model-based gaze estimation: Guestrin & Eizenman 2006, one camera, one or two (or more) LEDs.

E. D. Guestrin, M. Eizenman, "General theory of remote gaze estimation using the pupil center and
corneal reflections", IEEE TBME 53(6):1124-1133, 2006. World frame of `geometry` (mm; x to the
subject's left, y up, z toward the screen). Corneal and pupil centres: see `cornea`.

Optic axis w = (p - c)/|p - c| = [cos(phi) sin(theta), sin(phi), cos(phi) cos(theta)], so
theta = atan2(w_x, w_z) and phi = asin(w_y). Visual axis by the 2006 paper's ANGLE-ADDITION form
(adapted to z pointing toward the screen; not the thesis's rotation-matrix form, which differs by
0.07 to 0.14 deg at typical gaze angles):
    nu = [cos(phi+beta) sin(theta+alpha), sin(phi+beta), cos(phi+beta) cos(theta+alpha)].
Positive alpha turns the visual axis toward +x, nasal for a right eye: a right eye has alpha about
+5 deg, a left eye about -5 deg. Point of gaze g = c + k_g nu on the screen plane.

Personal calibration: bounded least squares (scipy.optimize.least_squares, trust-region reflective)
of the on-screen error (mm, x and y per target; objective "screen") or of the angular error (the
chord unit(target - c) - nu, about the angle in rad; objective "angular") over the calibration
targets, in (R, K, alpha, beta) and optionally n1. Bounds R [3, 20] mm, K [2, 15] mm, alpha
[-10, 10] deg, beta [-5, 5] deg (n1 [1.2, 1.6] when fitted); start R 7.8, K 4.2, alpha +5 (right) /
-5 (left), beta 1.5. Note: least squares minimises the summed squared error, not its mean.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from eyehil.drivers.gaze.base import Calibration, CalibrationFailure, EyeSamples, check_targets
from eyehil.drivers.gaze.cornea import corneal_centre, corneal_centre_one_led, pupil_centre
from eyehil.drivers.gaze.geometry import TrackerGeometry

#: Bounds of the calibrated parameters (mm, mm, deg, deg, dimensionless).
BOUNDS: Mapping[str, tuple[float, float]] = {
    "R": (3.0, 20.0),
    "K": (2.0, 15.0),
    "alpha_deg": (-10.0, 10.0),
    "beta_deg": (-5.0, 5.0),
    "n1": (1.2, 1.6),
}
#: Residual (mm or chord) standing in for a sample whose eye cannot be reconstructed.
_MISSING_RESIDUAL = 1e3


@dataclass(frozen=True)
class EyeParameters:
    """Personal eye parameters: corneal radius R (mm), K = |p - c| (mm), alpha and beta (deg), n1."""

    R: float = 7.8
    K: float = 4.2
    alpha_deg: float = 5.0
    beta_deg: float = 1.5
    n1: float = 1.3375

    @classmethod
    def start(cls, eye: Literal["right", "left"], n1: float = 1.3375) -> EyeParameters:
        """The published start: R 7.8, K 4.2, alpha +5 (right eye) or -5 (left eye), beta 1.5."""
        return cls(alpha_deg=5.0 if eye == "right" else -5.0, n1=n1)


def optic_axis_angles(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) in rad of unit optic axes w (..., 3): theta = atan2(w_x, w_z), phi = asin(w_y)."""
    return np.arctan2(w[..., 0], w[..., 2]), np.arcsin(np.clip(w[..., 1], -1.0, 1.0))


def visual_axis(w: np.ndarray, alpha_deg, beta_deg) -> np.ndarray:
    """Unit visual axis nu (..., 3) from optic axis w (..., 3) by the 2006 angle-addition form."""
    theta, phi = optic_axis_angles(w)
    theta = theta + np.radians(alpha_deg)
    phi = phi + np.radians(beta_deg)
    return np.stack([np.cos(phi) * np.sin(theta), np.sin(phi), np.cos(phi) * np.cos(theta)], axis=-1)


def reconstruct(
    geometry: TrackerGeometry, samples: EyeSamples, params: EyeParameters, eye_distance_mm=None
) -> tuple[np.ndarray, np.ndarray]:
    """Corneal centre c and visual axis nu (*shape, 3) world; NaN for invalid samples.

    With one LED, eye_distance_mm = |c - o| (mm, scalar or batch-broadcastable) is required.
    """
    if samples.n_leds != geometry.n_leds:
        raise ValueError(f"samples carry {samples.n_leds} glints, the geometry has {geometry.n_leds} LEDs")
    camera = geometry.camera
    centre_px = camera.K[:2, 2]  # a finite stand-in for invalid samples (masked below; SVD rejects NaN)
    glints = np.where(samples.valid[..., None, None], samples.glints_px, centre_px)
    pupil = np.where(samples.valid[..., None], samples.pupil_px, centre_px)
    if geometry.n_leds == 1:
        if eye_distance_mm is None:
            raise ValueError("one LED: eye_distance_mm (camera nodal point to corneal centre) is required")
        c = corneal_centre_one_led(camera, geometry.leds[0], glints[..., 0, :], params.R, eye_distance_mm)
    else:
        c = corneal_centre(camera, geometry.leds, glints, params.R)
    p = pupil_centre(camera, pupil, c, params.R, params.K, params.n1)
    w = (p - c) / np.linalg.norm(p - c, axis=-1, keepdims=True)
    nu = visual_axis(w, params.alpha_deg, params.beta_deg)
    invalid = ~samples.valid[..., None]
    return np.where(invalid, np.nan, c), np.where(invalid, np.nan, nu)


def point_of_gaze(geometry: TrackerGeometry, samples: EyeSamples, params: EyeParameters, eye_distance_mm=None):
    """Point of gaze (*shape, 2) screen mm: the visual axis c + k nu meets the screen plane."""
    c, nu = reconstruct(geometry, samples, params, eye_distance_mm)
    return geometry.screen.intersect(c, nu)


@dataclass(frozen=True, eq=False)
class GuestrinCalibration(Calibration[EyeSamples]):
    """A calibrated Guestrin estimator: fitted `parameters` and fit diagnostics.

    `fitted` names the calibrated parameters; `cost` = 0.5 sum of squared residuals (mm^2 or rad^2);
    `eye_distance_mm` is used only with one LED (replace it when the head moves).
    """

    geometry: TrackerGeometry
    parameters: EyeParameters
    fitted: tuple[str, ...]
    objective: str
    cost: float
    n_targets: int
    eye_distance_mm: float | np.ndarray | None = None

    @property
    def params(self) -> Mapping[str, object]:
        """R (mm), K (mm), alpha_deg, beta_deg, n1, and what was fitted how."""
        return {**asdict(self.parameters), "fitted": self.fitted, "objective": self.objective, "cost": self.cost}

    def estimate(self, samples: EyeSamples) -> np.ndarray:
        """Point of gaze (*shape, 2) screen mm."""
        return point_of_gaze(self.geometry, samples, self.parameters, self.eye_distance_mm)

    def with_eye_distance(self, eye_distance_mm) -> GuestrinCalibration:
        """The same calibration with another camera-to-corneal-centre distance (one-LED mode)."""
        return replace(self, eye_distance_mm=eye_distance_mm)


@dataclass(frozen=True, eq=False)
class GuestrinEstimator:
    """Calibrates (R, K, alpha, beta) [and n1 when `fit_n1`] of one eye on a known tracker geometry.

    `eye` sets the sign of the start alpha; `n1` is the corneal index used (and the start when
    fitted); `eye_distance_mm` (|c - o|, mm) is required with one LED; `start` overrides the start.
    """

    geometry: TrackerGeometry
    eye: Literal["right", "left"] = "right"
    n1: float = 1.3375
    fit_n1: bool = False
    objective: Literal["screen", "angular"] = "screen"
    eye_distance_mm: float | np.ndarray | None = None
    start: EyeParameters | None = None
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=lambda: dict(BOUNDS))

    def __post_init__(self) -> None:
        if self.eye not in ("right", "left"):
            raise ValueError(f"eye must be 'right' or 'left', got {self.eye!r}")
        if self.objective not in ("screen", "angular"):
            raise ValueError(f"objective must be 'screen' or 'angular', got {self.objective!r}")
        if self.geometry.n_leds == 1 and self.eye_distance_mm is None:
            raise ValueError("one LED: eye_distance_mm (camera nodal point to corneal centre) is required")

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the calibrated parameters, in the order of the solver's vector."""
        return ("R", "K", "alpha_deg", "beta_deg", "n1") if self.fit_n1 else ("R", "K", "alpha_deg", "beta_deg")

    def _parameters(self, x: np.ndarray) -> EyeParameters:
        values = dict(zip(self.names, (float(v) for v in x), strict=True))
        return EyeParameters(**{"n1": self.n1, **values})

    def _residuals(self, x: np.ndarray, samples: EyeSamples, targets: np.ndarray) -> np.ndarray:
        params = self._parameters(x)
        if self.objective == "screen":
            res = point_of_gaze(self.geometry, samples, params, self.eye_distance_mm) - targets
        else:
            c, nu = reconstruct(self.geometry, samples, params, self.eye_distance_mm)
            to_target = self.geometry.screen.to_world(targets) - c
            res = to_target / np.linalg.norm(to_target, axis=-1, keepdims=True) - nu
        return np.where(np.isfinite(res), res, _MISSING_RESIDUAL).ravel()

    def calibrate(self, samples: EyeSamples, targets_mm: np.ndarray) -> GuestrinCalibration | CalibrationFailure:
        """Fit on `samples` (*shape) fixating `targets_mm` (*shape, 2) screen mm; invalid samples are skipped."""
        targets = check_targets(targets_mm, samples.shape)
        if samples.n_leds != self.geometry.n_leds:
            raise ValueError(f"samples carry {samples.n_leds} glints, the geometry has {self.geometry.n_leds} LEDs")
        keep = samples.valid
        used = EyeSamples(samples.pupil_px[keep], samples.glints_px[keep])
        distance = self.eye_distance_mm
        if distance is not None and np.ndim(distance):
            distance = np.broadcast_to(distance, samples.shape)[keep]
        result = replace(self, eye_distance_mm=distance)._solve(used, targets[keep])
        return replace(result, eye_distance_mm=self.eye_distance_mm) if result else result

    def _solve(self, used: EyeSamples, targets: np.ndarray) -> GuestrinCalibration | CalibrationFailure:
        n_targets, names = used.shape[0], self.names
        if 2 * n_targets < len(names):
            return CalibrationFailure("guestrin", f"{n_targets} valid targets for {len(names)} parameters")
        x0 = np.array([getattr(self.start or EyeParameters.start(self.eye, self.n1), n) for n in names])
        lo, hi = np.array([self.bounds[n] for n in names]).T
        if np.any(self._residuals(x0, used, targets) == _MISSING_RESIDUAL):
            return CalibrationFailure("guestrin", "no eye reconstruction at the start parameters for some samples")
        # diff_step: the residuals come from inner iterative solves (corneal centre) whose noise at scipy's
        # default finite-difference step (~1.5e-8 relative) stopped fits early at non-minima; 1e-5 relative
        # makes float32-rounded and exact features calibrate to the same parameters (1e-5 deg apart).
        sol = least_squares(
            self._residuals, np.clip(x0, lo, hi), bounds=(lo, hi), args=(used, targets), x_scale=np.ones(len(names)),
            xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000, diff_step=1e-5,
        )
        if sol.status <= 0:
            return CalibrationFailure("guestrin", f"no convergence: {sol.message}")
        return GuestrinCalibration(
            self.geometry, self._parameters(sol.x), names, self.objective, float(sol.cost), n_targets,
            self.eye_distance_mm,
        )
