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

Estimator options (`GuestrinOptions`; every choice where the published study's code and the 2006
text or eyehil differ, each documented at its field) and two named profiles (`PROFILES`):
"best" (eyehil's own: least squares over both glints, angle addition, the screen plane, on-screen
error, n1 1.3375, least squares) and "study-code" (the estimator of Fischer et al. 2023's public
MATLAB code, Joshf17000548/EyeModels tests/Guestrin.m: the first LED's glint alone for the corneal
distance, rotation matrices for the visual axis, a gaze plane 1 mm behind the screen, the 3-D error,
pupil index 1.376 and a bounded minimisation of the sum of the calibration targets' errors).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from types import MappingProxyType
from typing import Literal

import numpy as np
from scipy.optimize import least_squares, minimize

from eyehil.drivers.gaze.base import (
    STUDY_VIEWING_DISTANCE_MM,
    Calibration,
    CalibrationFailure,
    EyeSamples,
    check_targets,
)
from eyehil.drivers.gaze.cornea import corneal_centre, corneal_centre_one_led, pupil_centre
from eyehil.drivers.gaze.geometry import Screen, TrackerGeometry

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

CornealDistance = Literal["all-glints"] | int
VisualAxisForm = Literal["angle-addition", "rotation"]
ErrorMetric = Literal["on-screen", "3-d"]
Objective = Literal["screen", "angular", "sum-of-errors"]


@dataclass(frozen=True)
class GuestrinOptions:
    """The estimator's choices, each a named option with its physics.

    corneal_distance: how k_c = |c - o| along the common direction b^ is found (`cornea`).
        "all-glints" (least squares of every glint's reflection law) or an LED index i (the root of
        glint i's law alone). Identical on a spherical cornea; on an aspheric one the one-glint
        distance carries that glint's asphericity bias in full (the published study's code used
        LED 0, the one at +188.5 mm, nasal for the right eye).
    visual_axis: how (alpha, beta) turn the optic axis w into the visual axis nu.
        "angle-addition" (the 2006 paper: theta + alpha, phi + beta) or "rotation" (rotation
        matrices about fixed world axes, beta about x (up) first, then alpha about y (toward +x)):
        nu = R_y(alpha) R_x(-beta) w, one rigid rotation of every optic axis. Both give the same nu
        for w = +z (straight ahead) and differ by a few hundredths of a degree at the screen's corners.
    gaze_plane_offset_mm: the point of gaze is the visual axis met with the screen plane moved this
        far along its normal (away from the subject when positive; the study's code: +1 mm, a plane
        at 651 mm for a screen at 650 mm); screen coordinates are its orthogonal projection.
    error_metric: "on-screen" (atan(|estimate - target| on the screen / 650 mm)) or "3-d" (atan(3-D
        distance from the point on the gaze plane to the target / 650 mm): with an offset plane the
        depth gap is always inside it, so a perfect estimate still has error atan(offset / 650)).
    n1: refractive index the estimator uses for the pupil ray (cornea + aqueous as one medium).
    objective: what calibration minimises. "screen": least squares of the on-screen residuals (mm,
        x and y per target); "angular": least squares of the chord unit(target - c) - nu; "sum-of-
        errors": the sum of the targets' errors in `error_metric` (deg), as the study's fmincon did
        (solved as least squares of sqrt(error), which has the same minimiser).
    """

    corneal_distance: str | int = "all-glints"
    visual_axis: str = "angle-addition"
    gaze_plane_offset_mm: float = 0.0
    error_metric: str = "on-screen"
    n1: float = 1.3375
    objective: str = "screen"

    def __post_init__(self) -> None:
        if self.corneal_distance != "all-glints" and not (
                isinstance(self.corneal_distance, int | np.integer) and self.corneal_distance >= 0):
            raise ValueError(f"corneal_distance must be 'all-glints' or an LED index, got {self.corneal_distance!r}")
        if self.visual_axis not in ("angle-addition", "rotation"):
            raise ValueError(f"visual_axis must be 'angle-addition' or 'rotation', got {self.visual_axis!r}")
        if self.error_metric not in ("on-screen", "3-d"):
            raise ValueError(f"error_metric must be 'on-screen' or '3-d', got {self.error_metric!r}")
        if self.objective not in ("screen", "angular", "sum-of-errors"):
            raise ValueError(f"objective must be 'screen', 'angular' or 'sum-of-errors', got {self.objective!r}")
        if not (np.isfinite(self.gaze_plane_offset_mm) and abs(self.gaze_plane_offset_mm) < 100.0):
            raise ValueError("gaze_plane_offset_mm must be finite and below 100 mm")
        if not 1.0 <= self.n1 <= 2.0:
            raise ValueError(f"n1 must be in [1, 2], got {self.n1}")


#: The named profiles: eyehil's own estimator and the one the published study's code ran.
PROFILES: Mapping[str, GuestrinOptions] = MappingProxyType({
    "best": GuestrinOptions(),
    "study-code": GuestrinOptions(corneal_distance=0, visual_axis="rotation", gaze_plane_offset_mm=1.0,
                                  error_metric="3-d", n1=1.376, objective="sum-of-errors"),
})


def profile(name: str) -> GuestrinOptions:
    """The options of a named profile (`PROFILES`)."""
    if name not in PROFILES:
        raise ValueError(f"unknown Guestrin profile {name!r}; known: {', '.join(PROFILES)}")
    return PROFILES[name]


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


def visual_axis(w: np.ndarray, alpha_deg, beta_deg, form: str = "angle-addition") -> np.ndarray:
    """Unit visual axis nu (..., 3) from optic axis w (..., 3): the 2006 angle-addition form, or with
    form="rotation" nu = R_y(alpha) R_x(-beta) w (fixed world axes; see `GuestrinOptions`)."""
    if form == "rotation":
        a, b = np.radians(alpha_deg), np.radians(beta_deg)
        ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
        vx, vy, vz = w[..., 0], cb * w[..., 1] + sb * w[..., 2], -sb * w[..., 1] + cb * w[..., 2]
        return np.stack([ca * vx + sa * vz, vy, -sa * vx + ca * vz], axis=-1)
    if form != "angle-addition":
        raise ValueError(f"visual axis form must be 'angle-addition' or 'rotation', got {form!r}")
    theta, phi = optic_axis_angles(w)
    theta = theta + np.radians(alpha_deg)
    phi = phi + np.radians(beta_deg)
    return np.stack([np.cos(phi) * np.sin(theta), np.sin(phi), np.cos(phi) * np.cos(theta)], axis=-1)


def reconstruct(
    geometry: TrackerGeometry, samples: EyeSamples, params: EyeParameters, eye_distance_mm=None,
    options: GuestrinOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Corneal centre c and visual axis nu (*shape, 3) world; NaN for invalid samples.

    With one LED, eye_distance_mm = |c - o| (mm, scalar or batch-broadcastable) is required.
    `options` (default: the "best" profile) chooses the corneal distance and the visual-axis form;
    the pupil index is `params.n1`. Parameters broadcast against the batch shape.
    """
    options = options or PROFILES["best"]
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
        c = corneal_centre(camera, geometry.leds, glints, params.R, options.corneal_distance)
    p = pupil_centre(camera, pupil, c, params.R, params.K, params.n1)
    w = (p - c) / np.linalg.norm(p - c, axis=-1, keepdims=True)
    nu = visual_axis(w, params.alpha_deg, params.beta_deg, options.visual_axis)
    invalid = ~samples.valid[..., None]
    return np.where(invalid, np.nan, c), np.where(invalid, np.nan, nu)


def gaze_plane(geometry: TrackerGeometry, offset_mm: float = 0.0) -> Screen:
    """The plane the point of gaze is taken on: the screen moved `offset_mm` along its normal."""
    screen = geometry.screen
    if offset_mm == 0.0:
        return screen
    return replace(screen, centre=screen.centre + offset_mm * screen.normal)


def point_of_gaze(geometry: TrackerGeometry, samples: EyeSamples, params: EyeParameters, eye_distance_mm=None,
                  options: GuestrinOptions | None = None):
    """Point of gaze (*shape, 2) screen mm: the visual axis c + k nu meets the gaze plane (`gaze_plane`)."""
    options = options or PROFILES["best"]
    c, nu = reconstruct(geometry, samples, params, eye_distance_mm, options)
    return gaze_plane(geometry, options.gaze_plane_offset_mm).intersect(c, nu)


def gaze_error_deg(estimates_mm: np.ndarray, targets_mm: np.ndarray, options: GuestrinOptions | None = None,
                   viewing_distance_mm: float = STUDY_VIEWING_DISTANCE_MM) -> np.ndarray:
    """Per-fixation error (deg) in the options' error metric (`GuestrinOptions.error_metric`).

    estimates_mm (screen mm on the gaze plane, as `point_of_gaze` returns) and targets_mm broadcast.
    "on-screen": atan(|estimate - target| / 650 mm); "3-d": atan(sqrt(|estimate - target|^2 +
    offset^2) / 650 mm), the 3-D distance from the point on the offset gaze plane to the target.
    """
    options = options or PROFILES["best"]
    d2 = np.sum((np.asarray(estimates_mm, float) - np.asarray(targets_mm, float)) ** 2, axis=-1)
    if options.error_metric == "3-d":
        d2 = d2 + options.gaze_plane_offset_mm**2
    return np.degrees(np.arctan(np.sqrt(d2) / viewing_distance_mm))


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
    options: GuestrinOptions | None = None

    @property
    def params(self) -> Mapping[str, object]:
        """R (mm), K (mm), alpha_deg, beta_deg, n1, and what was fitted how."""
        return {**asdict(self.parameters), "fitted": self.fitted, "objective": self.objective, "cost": self.cost}

    def estimate(self, samples: EyeSamples) -> np.ndarray:
        """Point of gaze (*shape, 2) screen mm (on the options' gaze plane)."""
        return point_of_gaze(self.geometry, samples, self.parameters, self.eye_distance_mm, self.options)

    def errors_deg(self, samples: EyeSamples, targets_mm: np.ndarray) -> np.ndarray:
        """Error (*shape) deg of the estimates at `targets_mm` in the options' error metric."""
        return gaze_error_deg(self.estimate(samples), targets_mm, self.options)

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
    objective: Literal["screen", "angular", "sum-of-errors"] = "screen"
    eye_distance_mm: float | np.ndarray | None = None
    start: EyeParameters | None = None
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=lambda: dict(BOUNDS))
    options: GuestrinOptions | None = None

    def __post_init__(self) -> None:
        if self.eye not in ("right", "left"):
            raise ValueError(f"eye must be 'right' or 'left', got {self.eye!r}")
        if self.options is None:
            object.__setattr__(self, "options", GuestrinOptions(n1=self.n1, objective=self.objective))
        else:  # the options carry the index and the objective
            object.__setattr__(self, "n1", self.options.n1)
            object.__setattr__(self, "objective", self.options.objective)
        if self.geometry.n_leds == 1 and self.eye_distance_mm is None:
            raise ValueError("one LED: eye_distance_mm (camera nodal point to corneal centre) is required")

    @classmethod
    def from_profile(cls, geometry: TrackerGeometry, name: str = "best", **kwargs) -> GuestrinEstimator:
        """The estimator of a named profile (`PROFILES`: "best" or "study-code")."""
        return cls(geometry, options=profile(name), **kwargs)

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the calibrated parameters, in the order of the solver's vector."""
        return ("R", "K", "alpha_deg", "beta_deg", "n1") if self.fit_n1 else ("R", "K", "alpha_deg", "beta_deg")

    def _parameters(self, x: np.ndarray) -> EyeParameters:
        values = dict(zip(self.names, (float(v) for v in x), strict=True))
        return EyeParameters(**{"n1": self.n1, **values})

    def _residuals(self, x: np.ndarray, samples: EyeSamples, targets: np.ndarray) -> np.ndarray:
        params, options = self._parameters(x), self.options
        if self.objective == "screen":
            res = point_of_gaze(self.geometry, samples, params, self.eye_distance_mm, options) - targets
        else:
            c, nu = reconstruct(self.geometry, samples, params, self.eye_distance_mm, options)
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
        if self.objective == "sum-of-errors":
            return self._minimise(used, targets, x0, lo, hi)
        sol = least_squares(
            self._residuals, np.clip(x0, lo, hi), bounds=(lo, hi), args=(used, targets), x_scale=np.ones(len(names)),
            xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000, diff_step=1e-5,
        )
        if sol.status <= 0:
            return CalibrationFailure("guestrin", f"no convergence: {sol.message}")
        return GuestrinCalibration(
            self.geometry, self._parameters(sol.x), names, self.objective, float(sol.cost), n_targets,
            self.eye_distance_mm, self.options,
        )

    def _minimise(self, used: EyeSamples, targets: np.ndarray, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray
                  ) -> GuestrinCalibration | CalibrationFailure:
        """The "sum-of-errors" objective: bounded quasi-Newton (L-BFGS-B) on the sum of the targets' errors."""
        def total(x: np.ndarray) -> float:
            estimate = point_of_gaze(self.geometry, used, self._parameters(x), self.eye_distance_mm, self.options)
            e = gaze_error_deg(estimate, targets, self.options)
            return float(np.sum(np.where(np.isfinite(e), e, _MISSING_RESIDUAL)))

        sol = minimize(total, np.clip(x0, lo, hi), method="L-BFGS-B", bounds=list(zip(lo, hi, strict=True)),
                       options={"ftol": 1e-15, "gtol": 1e-10, "maxiter": 2000, "eps": 1e-7})
        if not np.isfinite(sol.fun) or sol.fun >= _MISSING_RESIDUAL:
            return CalibrationFailure("guestrin", f"no convergence: {sol.message}")
        return GuestrinCalibration(
            self.geometry, self._parameters(sol.x), self.names, self.objective, float(sol.fun), used.shape[0],
            self.eye_distance_mm, self.options,
        )
