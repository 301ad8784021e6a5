"""EyeModel: the anatomy of one eye, or of a batch of eyes (struct of arrays).

Frame: the eye frame of DESIGN.md, origin at the unrotated anterior corneal apex, z forward (depth is
negative into the eye), x to the subject's left, y up. Every length is in mm, every angle in degrees.

Anatomical fields are stored as for a right eye; `left` says which eyes are left eyes, and everything
that is not rotationally symmetric (fovea angle, rotation centres, pupil decentration) is mirrored in
x for them. "Nasal" is +x for a right eye and -x for a left eye.

Every field is a numpy array; a single eye has 0-d scalar fields (vector fields shape (3,) or (2,)),
a batch of E eyes has fields of shape (E,) (vectors (E, 3), (E, 2)). `EyeModel.stack` builds a batch,
`eyes[i]` takes one eye back out.

The posterior segment follows gkaModelEye (Aguirre 2019, Sci Rep 9:9360) with the scaling of the
published study (Fischer et al. 2023); see `posterior.py`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

VECTOR_FIELDS = {"azimuth_centre": 3, "elevation_centre": 3, "pupil_decentre": 2}


@dataclass(frozen=True, eq=False)
class EyeModel:
    """Anatomy of one eye or a batch of eyes (mm, degrees; see the module docstring)."""

    anterior_radius: np.ndarray  # R_ac, vertex radius of the anterior cornea
    anterior_conic: np.ndarray  # Q_ac, conic constant (Q = -e^2; ellipsoid needs Q > -1)
    posterior_radius: np.ndarray  # R_pc
    posterior_conic: np.ndarray  # Q_pc
    cct: np.ndarray  # central corneal thickness
    acd: np.ndarray  # anterior chamber depth, posterior cornea to anterior lens (Rozema)
    pupil_radius: np.ndarray  # radius of the aperture stop (anatomical pupil)
    lens_anterior_radius: np.ndarray  # R_la > 0
    lens_posterior_radius: np.ndarray  # |R_lp| > 0 (the surface is concave toward the retina)
    lens_thickness: np.ndarray
    lens_index: np.ndarray  # crystalline lens, dimensionless
    axial_length: np.ndarray  # anterior corneal apex to the posterior pole of the retina
    alpha_h: np.ndarray  # fovea angle: line of sight vs optic axis, horizontal, + nasal (deg)
    alpha_v: np.ndarray  # vertical, + superior (deg)
    azimuth_centre: np.ndarray  # (..., 3) eye frame of a right eye (x nasal)
    elevation_centre: np.ndarray  # (..., 3)
    left: np.ndarray  # bool: a left eye (mirror image of the stored right-eye anatomy)
    limbus_radius: np.ndarray = field(default_factory=lambda: np.asarray(5.9))  # edge of the cornea
    pupil_decentre: np.ndarray = field(default_factory=lambda: np.zeros(2))  # (x nasal, y up) of a right eye

    def __post_init__(self) -> None:
        for f in fields(self):
            value = np.asarray(getattr(self, f.name), dtype=bool if f.name == "left" else float)
            object.__setattr__(self, f.name, value)
        self._validate()

    # --- construction -------------------------------------------------------------------------
    @classmethod
    def stack(cls, eyes: list[EyeModel]) -> EyeModel:
        """One batch of all `eyes` (each a single eye or a batch), concatenated in order."""
        if not eyes:
            raise ValueError("EyeModel.stack needs at least one eye")
        columns: dict[str, Any] = {}
        for f in fields(cls):
            parts = [np.asarray(getattr(e, f.name)) for e in eyes]
            ndim = 1 if f.name in VECTOR_FIELDS else 0
            parts = [p[None] if p.ndim == ndim else p for p in parts]
            columns[f.name] = np.concatenate(parts, axis=0)
        return cls(**columns)

    def __getitem__(self, index: Any) -> EyeModel:
        if self.anterior_radius.ndim == 0:
            raise TypeError("a single EyeModel cannot be indexed")
        return replace(self, **{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def __len__(self) -> int:
        if self.anterior_radius.ndim == 0:
            raise TypeError("a single EyeModel has no len(); use .shape")
        return int(self.anterior_radius.shape[0])

    @property
    def shape(self) -> tuple[int, ...]:
        return self.anterior_radius.shape

    def as_batch(self) -> EyeModel:
        """A batch (shape (E,)) view: a single eye becomes a batch of one."""
        return self if self.anterior_radius.ndim else EyeModel.stack([self])

    def mirrored(self) -> EyeModel:
        """The same anatomy as the other eye (right <-> left)."""
        return replace(self, left=~self.left)

    def with_laterality(self, side: str) -> EyeModel:
        """This anatomy as a `"right"` or `"left"` eye."""
        if side not in ("right", "left"):
            raise ValueError(f"laterality must be 'right' or 'left', not {side!r}")
        return replace(self, left=np.full(self.shape, side == "left"))

    def replace(self, **changes: Any) -> EyeModel:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    # --- derived quantities -------------------------------------------------------------------
    @property
    def side_sign(self) -> np.ndarray:
        """+1 for a right eye, -1 for a left eye: multiply a right-eye x (nasal) by it."""
        return np.where(self.left, -1.0, 1.0)

    @property
    def stop_depth(self) -> np.ndarray:
        """Depth of the aperture stop (pupil plane) behind the anterior apex: CCT + ACD."""
        return self.cct + self.acd

    @property
    def spherical_refraction(self) -> np.ndarray:
        """SR (D) from axial length, Atchison 2006: (23.58 - AL) / 0.299."""
        return (23.58 - self.axial_length) / 0.299

    @property
    def vitreous_length(self) -> np.ndarray:
        """AL - ACD - CCT - lens thickness (mm)."""
        return self.axial_length - self.acd - self.cct - self.lens_thickness

    def frame_vector(self, right_eye_vector: np.ndarray) -> np.ndarray:
        """A right-eye (..., 3) vector in this eye's frame: x multiplied by `side_sign`."""
        v = np.array(right_eye_vector, dtype=float, copy=True)
        v[..., 0] *= self.side_sign
        return v

    def describe(self) -> str:
        """One readable line per eye."""
        e = self.as_batch()
        lines = []
        for i in range(len(e)):
            lines.append(
                f"{'left ' if e.left[i] else 'right'} R_ac {e.anterior_radius[i]:.3f} Q_ac "
                f"{e.anterior_conic[i]:+.3f} R_pc {e.posterior_radius[i]:.3f} Q_pc {e.posterior_conic[i]:+.3f} "
                f"CCT {e.cct[i]:.3f} ACD {e.acd[i]:.3f} pupil {2 * e.pupil_radius[i]:.2f} "
                f"AL {e.axial_length[i]:.2f} alpha ({e.alpha_h[i]:.2f}, {e.alpha_v[i]:.2f}) deg"
            )
        return "\n".join(lines)

    # --- validation ---------------------------------------------------------------------------
    def _validate(self) -> None:
        shape = self.anterior_radius.shape
        for f in fields(self):
            value = getattr(self, f.name)
            want = shape + ((VECTOR_FIELDS[f.name],) if f.name in VECTOR_FIELDS else ())
            if value.shape != want:
                raise ValueError(f"EyeModel.{f.name} has shape {value.shape}, expected {want}")
            if f.name != "left" and not np.all(np.isfinite(value)):
                raise ValueError(f"EyeModel.{f.name} is not finite: {value}")
        positive = ("anterior_radius", "posterior_radius", "cct", "acd", "pupil_radius",
                    "lens_anterior_radius", "lens_posterior_radius", "lens_thickness", "axial_length",
                    "limbus_radius")
        for name in positive:
            bad = getattr(self, name) <= 0
            if np.any(bad):
                raise ValueError(f"EyeModel.{name} must be > 0 mm; got {getattr(self, name)[bad]}")
        for name in ("anterior_conic", "posterior_conic"):
            bad = getattr(self, name) <= -1
            if np.any(bad):
                raise ValueError(
                    f"EyeModel.{name} = {getattr(self, name)[bad]}: the cornea must be an ellipsoid "
                    "(Q = -e^2 > -1, i.e. eccentricity |e| < 1)"
                )
        if np.any(self.lens_index <= 1):
            raise ValueError("EyeModel.lens_index must be > 1")
        if np.any(self.pupil_radius >= self.limbus_radius):
            raise ValueError("EyeModel.pupil_radius must be smaller than limbus_radius")
        if np.any(self.vitreous_length <= 0):
            raise ValueError("EyeModel: axial length leaves no room for the vitreous (AL <= CCT+ACD+T)")
