"""Interpolation gaze mapping with a normalised pupil-glint vector: Blignaut 2014, binocular.

P. Blignaut, "Mapping the pupil-glint vector to gaze coordinates in a simple video-based eye
tracker", J Eye Mov Res 7(1):4, 2014, as replicated by Fischer et al. 2023.

Features (dimensionless), per eye and fixation, from one glint (LED `led`) in image px:
    v = (pupil centre - glint centre) / |pupil centre_right - pupil centre_left|,
the pupil-glint vector divided by the image distance between the two pupil centres.
Each eye has its own coefficients: screen X = sum_k a_k x^i_k y^j_k over the terms of the X form,
screen Y likewise with the Y form (forms: `forms.FORMS`), fitted by linear least squares over the
calibration targets (screen mm). The binocular estimate is the mean of the right and left
estimates. A fixation is used only when both eyes are valid (the normalisation needs both pupils).

Fitting: the design matrix's columns are scaled to unit maximum magnitude before the solve
(numpy lstsq, SVD); fewer targets than terms, or a rank-deficient design, is an explicit failure
unless `underdetermined="minimum_norm"` asks for the minimum-norm solution (what a Matlab-style
solver returns instead of failing; the published table lists errors for such fits at C5).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from eyehil.drivers.gaze.base import BinocularSamples, Calibration, CalibrationFailure, check_targets
from eyehil.drivers.gaze.forms import FORMS, MODELS, Form, design_matrix, resolve_form


def normalised_pupil_glint(samples: BinocularSamples, led: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Right and left features (*shape, 2): (pupil - glint[led]) px / interpupil image distance px."""
    right, left = samples.right, samples.left
    ipd = np.linalg.norm(right.pupil_px - left.pupil_px, axis=-1, keepdims=True)
    ipd = np.where(ipd > 0, ipd, np.nan)
    return (right.pupil_px - right.glints_px[..., led, :]) / ipd, (left.pupil_px - left.glints_px[..., led, :]) / ipd


def fit_form(
    form: Form, features: np.ndarray, values: np.ndarray, underdetermined: str = "fail"
) -> np.ndarray | str:
    """Coefficients (n_terms,) of `form` fitting values (n,) at features (n, 2); a reason string on failure."""
    A = design_matrix(form, features)
    n, m = A.shape
    if n == 0:
        return "no valid calibration fixations"
    scale = np.max(np.abs(A), axis=0)
    if np.any(scale == 0):
        return f"a term of {form} is zero at every calibration target"
    As = A / scale
    rank = np.linalg.matrix_rank(As)
    if rank < m and underdetermined == "fail":
        reason = f"{n} targets for {m} terms" if n < m else f"rank-deficient design (rank {rank} < {m} terms)"
        return reason
    coef = np.linalg.lstsq(As, values, rcond=None)[0]
    return coef / scale


@dataclass(frozen=True, eq=False)
class BlignautCalibration(Calibration[BinocularSamples]):
    """Fitted coefficients (screen mm per unit term) of both eyes.

    `coefficients[eye][axis]` with eye "right"/"left" and axis "x"/"y"; `rms_mm` is the per-eye
    root-mean-square calibration residual (mm) over both axes.
    """

    x_form: Form
    y_form: Form
    coefficients: Mapping[str, Mapping[str, np.ndarray]]
    led: int
    n_targets: int
    rms_mm: Mapping[str, float]

    @property
    def params(self) -> Mapping[str, object]:
        """Forms, coefficients and calibration residuals."""
        return {"x_form": self.x_form, "y_form": self.y_form, "coefficients": self.coefficients, "rms_mm": self.rms_mm}

    def _map(self, eye: str, features: np.ndarray) -> np.ndarray:
        coef = self.coefficients[eye]
        x = design_matrix(self.x_form, features) @ coef["x"]
        y = design_matrix(self.y_form, features) @ coef["y"]
        return np.stack([x, y], axis=-1)

    def estimate_per_eye(self, samples: BinocularSamples) -> tuple[np.ndarray, np.ndarray]:
        """Right and left estimates (*shape, 2) screen mm; NaN unless both eyes are valid."""
        right, left = normalised_pupil_glint(samples, self.led)
        invalid = ~samples.valid[..., None]
        return tuple(np.where(invalid, np.nan, self._map(e, f)) for e, f in (("right", right), ("left", left)))

    def estimate(self, samples: BinocularSamples) -> np.ndarray:
        """Binocular point of gaze (*shape, 2) screen mm: the mean of the right and left estimates."""
        right, left = self.estimate_per_eye(samples)
        return 0.5 * (right + left)


@dataclass(frozen=True, eq=False)
class BlignautEstimator:
    """Calibrates an (X form, Y form) pair; forms by name (looked up in `forms`) or as exponent tuples."""

    x_form: str | Form
    y_form: str | Form
    forms: Mapping[str, Form] = field(default_factory=lambda: FORMS)
    led: int = 0
    underdetermined: Literal["fail", "minimum_norm"] = "fail"

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_form", resolve_form(self.x_form, self.forms))
        object.__setattr__(self, "y_form", resolve_form(self.y_form, self.forms))
        if self.underdetermined not in ("fail", "minimum_norm"):
            raise ValueError(f"underdetermined must be 'fail' or 'minimum_norm', got {self.underdetermined!r}")

    @classmethod
    def from_model(cls, k: int, forms: Mapping[str, Form] = FORMS, models: Mapping[int, tuple[str, str]] = MODELS,
                   **kwargs) -> BlignautEstimator:
        """The estimator of published model k (`forms.MODELS`)."""
        if k not in models:
            raise ValueError(f"unknown model {k}; known: {sorted(models)}")
        return cls(*models[k], forms=forms, **kwargs)

    def _fit_eye(self, features: np.ndarray, targets: np.ndarray) -> tuple[dict[str, np.ndarray], float] | str:
        """Coefficients per screen axis and the RMS residual (mm) of one eye, or a failure reason."""
        fit: dict[str, np.ndarray] = {}
        for i, (axis, form) in enumerate((("x", self.x_form), ("y", self.y_form))):
            coef = fit_form(form, features, targets[:, i], self.underdetermined)
            if isinstance(coef, str):
                return f"screen {axis}: {coef}"
            fit[axis] = coef
        pred_x = design_matrix(self.x_form, features) @ fit["x"]
        pred = np.stack([pred_x, design_matrix(self.y_form, features) @ fit["y"]], axis=-1)
        return fit, float(np.sqrt(np.mean((pred - targets) ** 2)))

    def calibrate(self, samples: BinocularSamples, targets_mm: np.ndarray) -> BlignautCalibration | CalibrationFailure:
        """Fit each eye and screen axis on the fixations (*shape) at `targets_mm` (*shape, 2) screen mm.

        Fixations where either eye is invalid are skipped.
        """
        targets = check_targets(targets_mm, samples.shape)
        if not 0 <= self.led < samples.right.n_leds:
            raise ValueError(f"led {self.led} out of range for {samples.right.n_leds} glints")
        keep = samples.valid
        coefficients: dict[str, dict[str, np.ndarray]] = {}
        rms: dict[str, float] = {}
        for eye, features in zip(("right", "left"), normalised_pupil_glint(samples, self.led), strict=True):
            fit = self._fit_eye(features[keep], targets[keep])
            if isinstance(fit, str):
                return CalibrationFailure("blignaut", f"{eye} eye, {fit}")
            coefficients[eye], rms[eye] = fit
        return BlignautCalibration(self.x_form, self.y_form, coefficients, self.led, int(keep.sum()), rms)
