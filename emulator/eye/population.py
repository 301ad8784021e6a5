"""The Rozema 2011 stochastic population (SyntEyes): eyes drawn from a 17-parameter multivariate normal.

Source: Rozema, Atchison & Tassignon 2011, IOVS 52(7):4525-4533, doi:10.1167/iovs.10-6705; mean vector and
covariance embedded in `emulator/data/rozema2011.json` (see `rozema.py`). The covariance is numerically rank
deficient, so draws go through its eigendecomposition with eigenvalues clipped at zero.

Conversion to an eye (the published study's code, Fischer et al. 2023; lengths in mm, eye frame of `model.py`):
R_ac = 337.2 / K_ant_M, Q_ac = -ecc_ant^2, R_pc = (1337.2 - 1378) / K_post_M, Q_pc = -ecc_post^2, pupil radius
= pupil_diameter_scotopic / 2, ACD from the posterior cornea to the anterior lens, R_lp stored as |R_lp|.

Lens index: `"thick-lens"` (default, the paper's text) solves the thick-lens equation for n_L so that the lens
has the sampled power (`thick_lens_index` in `rozema.py`); a float fixes the index (the study's code: 1.42).

A draw is rejected, counted and redrawn when it cannot be an eye; each rejected draw counts once, under the
first failing reason of `REJECTION_REASONS`: a corneal surface that is not an ellipsoid (|e| >= 1), a
non-positive length or power (K_ant_M, -K_post_M, R_la, -R_lp, T, CCT, ACD, AL, pupil), a pupil at least as wide
as the cornea (limbus radius 5.9 mm), no room for the vitreous (AL <= CCT + ACD + T), no physical thick-lens index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.eye.biometry import eye_from_biometry
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.rozema import RawDraws, RozemaModel, rozema2011, thick_lens_index

__all__ = [
    "REJECTION_REASONS",
    "PopulationDraw",
    "eyes_from_raw",
    "parameter_table",
    "rejection_codes",
    "sample",
    "sample_raw",
    "study_parameters",
]

LIMBUS_RADIUS = 5.9  # mm, EyeModel's default edge of the cornea
REJECTION_REASONS = (
    "anterior_cornea_not_ellipsoid",
    "posterior_cornea_not_ellipsoid",
    "non_positive_length",
    "pupil_wider_than_cornea",
    "no_vitreous",
    "no_physical_lens_index",
)
#: Keys of `study_parameters`, in the order the sensitivity analysis uses (fischer2023_eyes.csv column names).
STUDY_KEYS = (
    "R_ant_cornea_mm", "Q_ant_cornea", "R_post_cornea_mm", "Q_post_cornea", "R_lens_ant_mm", "R_lens_post_mm",
    "CCT_mm", "ACD_mm", "lens_thickness_mm", "axial_length_mm", "pupil_diameter_mm",
)
#: Keys of `parameter_table`, in the order of Table 4 of Fischer et al. 2023.
TABLE4_KEYS = (
    "R_ant_cornea_mm", "Q_ant_cornea", "R_post_cornea_mm", "Q_post_cornea", "CCT_mm",
    "ACD_from_anterior_cornea_mm", "pupil_diameter_mm", "R_lens_ant_mm", "R_lens_post_mm", "n_lens",
    "lens_thickness_mm", "axial_length_mm",
)


@dataclass(frozen=True, eq=False)
class PopulationDraw:
    """n accepted eyes, their raw 17-parameter draws, and what was rejected on the way.

    `rejections` maps every reason of `REJECTION_REASONS` to the number of draws rejected for it;
    `attempts` = n + all rejections (the draws examined until the n-th acceptance).
    """

    eyes: EyeModel
    raw: RawDraws
    rejections: dict[str, int]
    attempts: int

    @property
    def n_rejected(self) -> int:
        return sum(self.rejections.values())

    @property
    def rejection_rate(self) -> float:
        """Fraction of the examined draws that were rejected."""
        return self.n_rejected / self.attempts

    def summary(self) -> str:
        """One line: accepted, rejected per reason (only the reasons that occurred)."""
        parts = [f"{k} {v}" for k, v in self.rejections.items() if v]
        detail = f" ({', '.join(parts)})" if parts else ""
        return f"{len(self.eyes)} eyes accepted, {self.n_rejected} of {self.attempts} draws rejected{detail}"


def sample_raw(n: int, rng: np.random.Generator, model: RozemaModel | None = None) -> RawDraws:
    """`n` raw draws of the 17 Rozema parameters (units of `rozema2011.json`), nothing rejected."""
    _check_n(n)
    return (model or rozema2011()).draw(n, rng)


def sample(
    n: int,
    rng: np.random.Generator,
    *,
    lens_index: str | float = "thick-lens",
    laterality: str = "right",
    fovea_scaling: str = "study",
    centre_scaling: str = "study",
    model: RozemaModel | None = None,
) -> PopulationDraw:
    """Draw `n` valid eyes (a batch EyeModel, mm and degrees) from the Rozema 2011 population.

    Impossible draws are rejected and redrawn until `n` are accepted; see `PopulationDraw.rejections`.
    `model` replaces the published population (e.g. `rozema2011().with_mean(...)` for tests).
    """
    _check_n(n)
    _check_lens_index(lens_index)
    model = model or rozema2011()
    kept, counts, attempts = [], np.zeros(len(REJECTION_REASONS) + 1, dtype=int), 0
    while (need := n - sum(len(k) for k in kept)) > 0:
        if attempts > 1000 * n + 100_000:
            raise RuntimeError(f"sample: gave up after {attempts} draws; rejections {_as_dict(counts)}")
        raw = model.draw(need + need // 10 + 16, rng)
        codes = rejection_codes(raw, lens_index)
        stop = int(np.searchsorted(np.cumsum(codes == 0), need)) + 1  # up to the need-th acceptance
        codes, raw = codes[:stop], raw[:stop]
        counts += np.bincount(codes, minlength=counts.size)
        attempts += codes.size
        kept.append(raw[codes == 0])
    raw = RawDraws(np.concatenate([k.values for k in kept]), model.names)
    eyes = eyes_from_raw(raw, lens_index, laterality, fovea_scaling, centre_scaling)
    return PopulationDraw(eyes=eyes, raw=raw, rejections=_as_dict(counts), attempts=attempts)


def rejection_codes(raw: RawDraws, lens_index: str | float = "thick-lens") -> np.ndarray:
    """Per draw: 0 if it is a valid eye, else 1 + the index in `REJECTION_REASONS` of its first failing reason."""
    _check_lens_index(lens_index)
    lengths = ("R_lens_ant", "lens_thickness", "CCT", "ACD", "axial_length", "pupil_diameter_scotopic", "K_ant_M")
    non_positive = np.any([raw[k] <= 0 for k in lengths], axis=0) | (raw["K_post_M"] >= 0) | (raw["R_lens_post"] >= 0)
    vitreous = raw["axial_length"] - raw["CCT"] - raw["ACD"] - raw["lens_thickness"]
    fails = [
        np.abs(raw["ecc_ant"]) >= 1,
        np.abs(raw["ecc_post"]) >= 1,
        non_positive,
        raw["pupil_diameter_scotopic"] / 2 >= LIMBUS_RADIUS,
        vitreous <= 0,
        ~np.isfinite(_lens_index(raw, lens_index)),
    ]
    table = np.column_stack([np.zeros(len(raw), dtype=bool), *fails])
    table[:, 0] = ~table[:, 1:].any(axis=1)
    return np.argmax(table, axis=1)


def eyes_from_raw(
    raw: RawDraws,
    lens_index: str | float = "thick-lens",
    laterality: str = "right",
    fovea_scaling: str = "study",
    centre_scaling: str = "study",
) -> EyeModel:
    """Convert raw draws (all valid: see `rejection_codes`) to a batch EyeModel with the study's conventions."""
    _check_lens_index(lens_index)
    return eye_from_biometry(
        anterior_radius=337.2 / raw["K_ant_M"],
        anterior_conic=-raw["ecc_ant"] ** 2,
        posterior_radius=(1337.2 - 1378.0) / raw["K_post_M"],
        posterior_conic=-raw["ecc_post"] ** 2,
        cct=raw["CCT"],
        acd=raw["ACD"],
        pupil_diameter=raw["pupil_diameter_scotopic"],
        lens_anterior_radius=raw["R_lens_ant"],
        lens_posterior_radius=np.abs(raw["R_lens_post"]),
        lens_thickness=raw["lens_thickness"],
        axial_length=raw["axial_length"],
        lens_index=_lens_index(raw, lens_index),
        laterality=laterality,
        fovea_scaling=fovea_scaling,
        centre_scaling=centre_scaling,
    )


def study_parameters(eyes: EyeModel) -> dict[str, np.ndarray]:
    """The 11 per-eye parameters of the sensitivity analysis, keyed by `STUDY_KEYS` (mm; ACD from the
    posterior cornea; R_lens_post as a magnitude; pupil diameter, not radius)."""
    e = eyes.as_batch()
    values = (
        e.anterior_radius, e.anterior_conic, e.posterior_radius, e.posterior_conic, e.lens_anterior_radius,
        e.lens_posterior_radius, e.cct, e.acd, e.lens_thickness, e.axial_length, 2.0 * e.pupil_radius,
    )
    return {k: np.array(v) for k, v in zip(STUDY_KEYS, values, strict=True)}


def parameter_table(eyes: EyeModel) -> dict[str, tuple[float, float]]:
    """Mean and SD (ddof=1) of the 12 parameters of Table 4 of Fischer et al. 2023, keyed by `TABLE4_KEYS`.

    ACD is measured there from the anterior cornea (CCT + ACD, the stop depth); n_lens is dimensionless.
    """
    e = eyes.as_batch()
    if len(e) < 2:
        raise ValueError("parameter_table needs at least two eyes (SD with ddof=1)")
    columns = study_parameters(e) | {"ACD_from_anterior_cornea_mm": e.stop_depth, "n_lens": e.lens_index}
    return {k: (float(np.mean(columns[k])), float(np.std(columns[k], ddof=1))) for k in TABLE4_KEYS}


def _lens_index(raw: RawDraws, lens_index: str | float) -> np.ndarray:
    """Per-draw lens index: thick-lens solution (NaN where none is physical) or the fixed value."""
    if isinstance(lens_index, str):
        return thick_lens_index(raw["lens_power"], raw["R_lens_ant"], raw["R_lens_post"], raw["lens_thickness"])
    return np.full(len(raw), float(lens_index))


def _check_lens_index(lens_index: str | float) -> None:
    if isinstance(lens_index, str):
        if lens_index != "thick-lens":
            raise ValueError(f"lens_index must be 'thick-lens' or a refractive index (float), not {lens_index!r}")
    elif not (np.isfinite(lens_index) and 1.0 < float(lens_index) < 3.0):
        raise ValueError(f"a fixed lens_index must be a refractive index in (1, 3), not {lens_index!r}")


def _check_n(n: int) -> None:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n <= 0:
        raise ValueError(f"n must be a positive integer, not {n!r}")


def _as_dict(counts: np.ndarray) -> dict[str, int]:
    return {reason: int(c) for reason, c in zip(REJECTION_REASONS, counts[1:], strict=True)}
