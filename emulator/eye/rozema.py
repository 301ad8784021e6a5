"""The Rozema 2011 statistical eye model (SyntEyes) as data, and the thick-lens index of its lenses.

Source: Rozema JJ, Atchison DA, Tassignon MJ. Statistical eye model for normal eyes. IOVS 2011;52(7):4525-4533,
doi:10.1167/iovs.10-6705. The 17 parameter names, units, means, SDs and the 17x17 covariance are read from
`emulator/data/rozema2011.json` (transcribed as published, full precision). Keratometry in dioptres, lengths in
mm, eccentricities dimensionless, R_lens_post negative, ACD from the posterior cornea.

Thick-lens index (Fischer et al. 2023, Eq. 2, after Rozema 2011): the lens index n such that a lens of radii
R_la > 0, R_lp < 0 and thickness T (mm) between media n_aq and n_vit has the power P (D):

    P = F1 + F2 - (T / n) F1 F2,  F1 = (n - n_aq) / R_la,  F2 = (n_vit - n) / R_lp      (lengths in m)

Multiplied by n R_la R_lp (lengths in mm, p = P / 1000 in 1/mm) this is a quadratic a n^2 + b n + c = 0 with
a = T - R_la + R_lp, b = n_vit R_la - n_aq R_lp - T (n_aq + n_vit) - p R_la R_lp, c = T n_aq n_vit.
When a < 0 (T < R_la + |R_lp|, every real lens) c / a < 0: one positive and one negative root, and the positive
one is the index. Known answer: at the population mean (R_la 10.427, R_lp -6.864, T 4.07, P 22.994) with
n_aq = n_vit = 1.336 (the study code's aqueous and vitreous) n = 1.4327, the reference's 1.433; 1.3374 gives
1.4341 and the Cauchy aqueous at 850 nm (1.3302) 1.4270, so 1.336 is the medium index behind that figure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

#: Aqueous and vitreous index used in the thick-lens equation (the study code's media; see module docstring).
THICK_LENS_MEDIUM_INDEX = 1.336
#: Largest lens index accepted as physical (a guard: the population's solutions lie in 1.38..1.49).
MAX_LENS_INDEX = 1.6


@dataclass(frozen=True, eq=False)
class RawDraws:
    """Raw draws of the Rozema parameters: `values` (n, 17) in the units of the data file, columns `names`.

    `draws["ACD"]` is a column (n,); `draws[mask]` or `draws[i:j]` selects draws.
    """

    values: np.ndarray
    names: tuple[str, ...]

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, str):
            return self.values[:, self.names.index(key)]
        return RawDraws(np.atleast_2d(self.values[key]), self.names)

    def __len__(self) -> int:
        return int(self.values.shape[0])

    def as_dict(self) -> dict[str, np.ndarray]:
        """Columns by name (copies)."""
        return {name: self.values[:, i].copy() for i, name in enumerate(self.names)}


@dataclass(frozen=True, eq=False)
class RozemaModel:
    """A multivariate normal population of eyes: parameter `names`, `units`, `mean`, `sd`, `covariance`."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    mean: np.ndarray
    sd: np.ndarray
    covariance: np.ndarray
    citation: str = ""

    def index(self, name: str) -> int:
        if name not in self.names:
            raise KeyError(f"unknown Rozema parameter {name!r}; known: {', '.join(self.names)}")
        return self.names.index(name)

    def draw(self, n: int, rng: np.random.Generator) -> RawDraws:
        """`n` draws, x = mean + V sqrt(max(w, 0)) z with C = V diag(w) V^T and z standard normal."""
        w, v = np.linalg.eigh(self.covariance)
        factor = v * np.sqrt(np.clip(w, 0.0, None))
        z = rng.standard_normal((n, self.mean.size))
        return RawDraws(self.mean + z @ factor.T, self.names)

    def mean_draw(self) -> RawDraws:
        """The mean vector as a single draw (a batch of one)."""
        return RawDraws(self.mean[None, :].copy(), self.names)

    def with_mean(self, **changes: float) -> RozemaModel:
        """The same covariance about a shifted mean (e.g. `with_mean(ecc_post=0.9)` to provoke rejections)."""
        mean = self.mean.copy()
        for name, value in changes.items():
            mean[self.index(name)] = value
        return replace(self, mean=mean)


@lru_cache(maxsize=1)
def rozema2011() -> RozemaModel:
    """The published population (Rozema, Atchison & Tassignon 2011), from the embedded data file."""
    text = resources.files("eyehil.emulator").joinpath("data", "rozema2011.json").read_text(encoding="utf-8")
    doc = json.loads(text)
    params = doc["parameters"]
    covariance = np.array(doc["covariance"], dtype=float)
    covariance.flags.writeable = False
    return RozemaModel(
        names=tuple(p["name"] for p in params),
        units=tuple(p["unit"] for p in params),
        mean=np.array([p["mean"] for p in params], dtype=float),
        sd=np.array([p["sd"] for p in params], dtype=float),
        covariance=covariance,
        citation=doc["citation"],
    )


def thick_lens_index(
    lens_power: np.ndarray | float,
    anterior_radius: np.ndarray | float,
    posterior_radius: np.ndarray | float,
    thickness: np.ndarray | float,
    n_aqueous: float = THICK_LENS_MEDIUM_INDEX,
    n_vitreous: float = THICK_LENS_MEDIUM_INDEX,
) -> np.ndarray:
    """Lens index giving `lens_power` (D) for radii R_la > 0, R_lp < 0 (signed) and `thickness` (mm).

    Vectorised closed form of the quadratic in the module docstring; NaN where no root is physical
    (a >= 0, or the root outside (max(n_aqueous, n_vitreous), MAX_LENS_INDEX)).
    """
    r1, r2 = np.asarray(anterior_radius, dtype=float), np.asarray(posterior_radius, dtype=float)
    t, p = np.asarray(thickness, dtype=float), np.asarray(lens_power, dtype=float) * 1e-3
    a = t - r1 + r2
    b = n_vitreous * r1 - n_aqueous * r2 - t * (n_aqueous + n_vitreous) - p * r1 * r2
    c = t * n_aqueous * n_vitreous
    with np.errstate(invalid="ignore", divide="ignore"):
        root = (-b - np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)  # the positive root when a < 0
    physical = (a < 0) & (root > max(n_aqueous, n_vitreous)) & (root < MAX_LENS_INDEX)
    return np.where(physical, root, np.nan)
