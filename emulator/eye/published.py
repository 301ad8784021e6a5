"""The 100 eyes of the published simulation (Fischer, van der Merwe & Vandenheever 2023, J Eye Mov Res 16(3)).

Biometry from `emulator/data/fischer2023_eyes.csv` (own copy, source in its header): per eye R_ac, Q_ac, R_pc,
Q_pc, R_la, |R_lp|, CCT, ACD (posterior cornea to lens), lens thickness, AL, pupil diameter; mm, Q dimensionless.
Running the replication on exactly these eyes allows an eye-by-eye comparison with the study.

Lens index. The file has no lens power, so the thick-lens index of `population.py` cannot be solved exactly.
- Default `1.42`: the fixed index of the study's own code, i.e. the index these eyes were traced with.
- `"thick-lens"`: an estimate. Each eye's lens power is its conditional mean under the Rozema 2011 normal given
  nine of its parameters (K_ant_M = 337.2 / R_ac, K_post_M = -40.8 / R_pc, R_la, -|R_lp|, T, CCT, ACD, AL, pupil;
  the eccentricities are left out because Q = -e^2 has lost their sign); the thick-lens equation then gives n_L.
  The conditional SD of the lens power is 1.47 D (about 0.006 in n_L), so it is not the study's value, only a
  principled guess; the estimate is also less dispersed than real indices.
- a float: that fixed index.

Hyperboloids. Eye 75 has Q_pc = -1.163 (|e| > 1): the study's ray tracer took it as a hyperboloid, but EyeModel
requires ellipsoids. `hyperboloids="clip"` (default) sets Q to -0.999 (posterior-surface sag changes by 0.018 mm
at 4 mm from the axis, 0.08 mm at 5.9 mm), `"drop"` leaves the eye out (99 eyes), `"raise"` refuses.
"""

from __future__ import annotations

import csv
import io
from functools import lru_cache
from importlib import resources

import numpy as np

from eyehil.emulator.eye.biometry import eye_from_biometry
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.rozema import rozema2011, thick_lens_index

__all__ = ["HYPERBOLOID_CLIP", "STUDY_LENS_INDEX", "conditional_lens_power", "published_biometry", "published_eyes"]

STUDY_LENS_INDEX = 1.42  # the published study's code
HYPERBOLOID_CLIP = -0.999  # conic constant given to corneal surfaces published with Q <= -1
_DATA_FILE = "fischer2023_eyes.csv"


@lru_cache(maxsize=1)
def _columns() -> dict[str, np.ndarray]:
    text = resources.files("eyehil.emulator").joinpath("data", _DATA_FILE).read_text(encoding="utf-8")
    rows = list(csv.reader(io.StringIO("".join(ln for ln in text.splitlines(True) if not ln.startswith("#")))))
    header, body = rows[0], np.array(rows[1:], dtype=float)
    columns = {name: body[:, i] for i, name in enumerate(header)}
    for values in columns.values():
        values.flags.writeable = False
    return columns


def published_biometry() -> dict[str, np.ndarray]:
    """The embedded table as published: columns by name (copies, shape (100,)); see the module docstring."""
    return {name: values.copy() for name, values in _columns().items()}


def conditional_lens_power(biometry: dict[str, np.ndarray]) -> np.ndarray:
    """E[lens power | nine parameters] (D) under the Rozema 2011 normal, for columns named as in the data file."""
    model = rozema2011()
    observed = {
        "K_ant_M": 337.2 / biometry["R_ant_cornea_mm"],
        "K_post_M": (1337.2 - 1378.0) / biometry["R_post_cornea_mm"],
        "R_lens_ant": biometry["R_lens_ant_mm"],
        "R_lens_post": -np.abs(biometry["R_lens_post_mm"]),
        "lens_thickness": biometry["lens_thickness_mm"],
        "CCT": biometry["CCT_mm"],
        "ACD": biometry["ACD_mm"],
        "axial_length": biometry["axial_length_mm"],
        "pupil_diameter_scotopic": biometry["pupil_diameter_mm"],
    }
    obs = [model.index(name) for name in observed]
    target = model.index("lens_power")
    gain = np.linalg.solve(model.covariance[np.ix_(obs, obs)], model.covariance[obs, target])
    deviation = np.column_stack(list(observed.values())) - model.mean[obs]
    return model.mean[target] + deviation @ gain


def published_eyes(
    laterality: str = "right",
    lens_index: str | float = STUDY_LENS_INDEX,
    *,
    hyperboloids: str = "clip",
    fovea_scaling: str = "study",
    centre_scaling: str = "study",
) -> EyeModel:
    """The published study's 100 eyes as a batch EyeModel (mm, degrees), in file order (eye 1 first)."""
    columns = published_biometry()
    columns = _handle_hyperboloids(columns, hyperboloids)
    return eye_from_biometry(
        anterior_radius=columns["R_ant_cornea_mm"],
        anterior_conic=columns["Q_ant_cornea"],
        posterior_radius=columns["R_post_cornea_mm"],
        posterior_conic=columns["Q_post_cornea"],
        cct=columns["CCT_mm"],
        acd=columns["ACD_mm"],
        pupil_diameter=columns["pupil_diameter_mm"],
        lens_anterior_radius=columns["R_lens_ant_mm"],
        lens_posterior_radius=columns["R_lens_post_mm"],
        lens_thickness=columns["lens_thickness_mm"],
        axial_length=columns["axial_length_mm"],
        lens_index=_lens_index(columns, lens_index),
        laterality=laterality,
        fovea_scaling=fovea_scaling,
        centre_scaling=centre_scaling,
    )


def _handle_hyperboloids(columns: dict[str, np.ndarray], how: str) -> dict[str, np.ndarray]:
    bad = (columns["Q_ant_cornea"] <= -1) | (columns["Q_post_cornea"] <= -1)
    if how == "clip":
        for key in ("Q_ant_cornea", "Q_post_cornea"):
            columns[key] = np.maximum(columns[key], HYPERBOLOID_CLIP)
        return columns
    if how == "drop":
        return {name: values[~bad] for name, values in columns.items()}
    if how == "raise":
        if bad.any():
            raise ValueError(f"published eyes {columns['eye'][bad].astype(int).tolist()} have a hyperboloid cornea")
        return columns
    raise ValueError(f"hyperboloids must be 'clip', 'drop' or 'raise', not {how!r}")


def _lens_index(columns: dict[str, np.ndarray], lens_index: str | float) -> np.ndarray | float:
    if isinstance(lens_index, str):
        if lens_index != "thick-lens":
            raise ValueError(f"lens_index must be 'thick-lens' or a refractive index (float), not {lens_index!r}")
        power = conditional_lens_power(columns)
        n = thick_lens_index(power, columns["R_lens_ant_mm"], -columns["R_lens_post_mm"], columns["lens_thickness_mm"])
        if not np.all(np.isfinite(n)):
            raise ValueError("no physical thick-lens index for some published eyes")
        return n
    if not (np.isfinite(lens_index) and 1.0 < float(lens_index) < 3.0):
        raise ValueError(f"a fixed lens_index must be a refractive index in (1, 3), not {lens_index!r}")
    return float(lens_index)
