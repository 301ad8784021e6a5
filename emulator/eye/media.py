"""Refractive indices of the ocular media.

Cauchy dispersion n(L) = c0 + c1/L^2 + c2/L^4 + c3/L^6 with L in nm; coefficients from gkaModelEye
(Aguirre 2019, after Navarro 2014, J Vis 14(13):21). The published study (Fischer et al. 2023) states
Cauchy indices at the LED wavelength (850 nm) in its text, while its code used fixed indices; both are
available and a scene or run names the one it uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Cauchy coefficients (c0, c1, c2, c3), L in nm. Source: gkaModelEye / Navarro 2014.
CAUCHY: dict[str, tuple[float, float, float, float]] = {
    "cornea": (1.362994, 6.009687e3, -6.760760e8, 5.908450e13),
    "aqueous": (1.323031, 6.070796e3, -7.062305e8, 6.147861e13),
    "tears": (1.321631, 6.070796e3, -7.062305e8, 6.147861e13),
    "vitreous": (1.323757, 5.560240e3, -5.817391e8, 5.036810e13),
    "lens_edge": (1.356086, 6.428455e3, -6.023738e8, 5.824149e13),
}


def cauchy_index(medium: str, wavelength_nm: float) -> float:
    """Refractive index of `medium` at `wavelength_nm` (Cauchy, table above).

    Known answer: cauchy_index("cornea", 850) = 1.37017 (reference table, 5 decimals).
    """
    if medium not in CAUCHY:
        raise ValueError(f"unknown medium {medium!r}; known: {', '.join(CAUCHY)}")
    if not 300.0 <= wavelength_nm <= 2000.0:
        raise ValueError(f"wavelength {wavelength_nm} nm is outside 300..2000 nm")
    c0, c1, c2, c3 = CAUCHY[medium]
    lam2 = float(wavelength_nm) ** 2
    return c0 + c1 / lam2 + c2 / lam2**2 + c3 / lam2**3


@dataclass(frozen=True)
class Media:
    """Indices of the media light crosses on its way out of the eye (dimensionless).

    `air` is the index outside the eye. The crystalline lens index is a property of each eye
    (`EyeModel.lens_index`), derived from its sampled lens power, not of the media.
    """

    cornea: float
    aqueous: float
    vitreous: float
    air: float = 1.0
    label: str = "custom"

    def __post_init__(self) -> None:
        for name in ("cornea", "aqueous", "vitreous", "air"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 1.0 <= value < 3.0):
                raise ValueError(f"Media.{name} = {value!r}: a refractive index must be in [1, 3)")

    @classmethod
    def cauchy(cls, wavelength_nm: float = 850.0) -> Media:
        """Cauchy indices at the illumination wavelength (the paper's text; default)."""
        return cls(
            cornea=cauchy_index("cornea", wavelength_nm),
            aqueous=cauchy_index("aqueous", wavelength_nm),
            vitreous=cauchy_index("vitreous", wavelength_nm),
            label=f"cauchy@{wavelength_nm:g}nm",
        )

    @classmethod
    def study_code(cls) -> Media:
        """Fixed indices of the published study's own code: cornea 1.337, aqueous/vitreous 1.336."""
        return cls(cornea=1.337, aqueous=1.336, vitreous=1.336, label="study-code")

    @classmethod
    def named(cls, name: str, wavelength_nm: float = 850.0) -> Media:
        """`"cauchy"` (at `wavelength_nm`) or `"study-code"`."""
        if name == "cauchy":
            return cls.cauchy(wavelength_nm)
        if name == "study-code":
            return cls.study_code()
        raise ValueError(f"unknown media {name!r}; use 'cauchy' or 'study-code'")
