"""EyeModel: the anatomy of one eye, or of a batch of eyes (struct of arrays).

Frame: the eye frame of DESIGN.md, origin at the unrotated anterior corneal apex, z forward (depth is
negative into the eye), x to the subject's left, y up. Every length is in mm, every angle in degrees.

Anatomical fields are stored as for a right eye; `left` says which eyes are left eyes, and everything
that is not rotationally symmetric (fovea angle, rotation centres, pupil decentration) is mirrored in
x for them. "Nasal" is +x for a right eye and -x for a left eye.

Every field is a numpy array; a single eye has 0-d scalar fields (vector fields shape (3,) or (2,)),
a batch of E eyes has fields of shape (E,) (vectors (E, 3), (E, 2)). `EyeModel.stack` builds a batch,
`eyes[i]` takes one eye back out.

Beyond the published study (all optional, neutral by default, see docs/physics.md "Eyes beyond the paper"):
- toric (biconic) corneal surfaces: `anterior_radius` / `anterior_conic` hold the principal meridian at
  `anterior_axis_deg` (TABO angle of a right eye: from +x nasal toward +y up, as the examiner sees a right
  eye), `anterior_radius_perp` / `anterior_conic_perp` the meridian 90 deg away (default: equal, a conic of
  revolution); the same for the posterior cornea;
- the whole cornea (both surfaces, rigidly) tilted about the anterior apex by `cornea_tilt_deg` = (h, v): its
  axis turns to (cos v sin h, sin v, cos v cos h), h nasal, v superior, and then displaced by `cornea_offset`
  (x nasal, y up, z forward; mm);
- an elliptical aperture stop: `pupil_eccentricity` e in [0, 1) with its major axis at `pupil_axis_deg`
  (from nasal toward superior), the area of the circle of `pupil_radius` (gkaModelEye's convention);
- `pupil_shift_per_mm`: how the stop centre moves per mm of pupil diameter increase (x nasal, y up), applied
  by `with_pupil_diameter`.
Left eyes mirror all of them (x -> -x: axis angles theta -> -theta, nasal tilt and offsets keep their
anatomical meaning). `rotationally_symmetric` says which eyes have none of the first three; those are traced
exactly as in the published study.

The posterior segment follows gkaModelEye (Aguirre 2019, Sci Rep 9:9360) with the scaling of the
published study (Fischer et al. 2023); see `posterior.py`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

VECTOR_FIELDS = {"azimuth_centre": 3, "elevation_centre": 3, "pupil_decentre": 2, "cornea_offset": 3,
                 "cornea_tilt_deg": 2, "pupil_shift_per_mm": 2}
#: Fields that default to a copy of another one (a conic of revolution unless given).
_DEFAULT_COPIES = {"anterior_radius_perp": "anterior_radius", "anterior_conic_perp": "anterior_conic",
                   "posterior_radius_perp": "posterior_radius", "posterior_conic_perp": "posterior_conic"}
MAX_CORNEA_TILT_DEG = 30.0


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
    anterior_radius_perp: np.ndarray | None = None  # R_ac in the meridian at anterior_axis_deg + 90
    anterior_conic_perp: np.ndarray | None = None
    anterior_axis_deg: np.ndarray = field(default_factory=lambda: np.asarray(0.0))  # meridian of anterior_radius
    posterior_radius_perp: np.ndarray | None = None
    posterior_conic_perp: np.ndarray | None = None
    posterior_axis_deg: np.ndarray = field(default_factory=lambda: np.asarray(0.0))
    cornea_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))  # anterior apex (x nasal, y up, z)
    cornea_tilt_deg: np.ndarray = field(default_factory=lambda: np.zeros(2))  # (h nasal, v superior)
    pupil_eccentricity: np.ndarray = field(default_factory=lambda: np.asarray(0.0))  # of the stop ellipse
    pupil_axis_deg: np.ndarray = field(default_factory=lambda: np.asarray(0.0))  # its major axis, nasal -> up
    pupil_shift_per_mm: np.ndarray = field(default_factory=lambda: np.zeros(2))  # centre shift / mm diameter

    def __post_init__(self) -> None:
        for name, source in _DEFAULT_COPIES.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.array(getattr(self, source), dtype=float, copy=True))
        shape = np.shape(self.anterior_radius)
        for f in fields(self):  # the optional scalars/vectors broadcast to the batch
            if f.name in ("anterior_axis_deg", "posterior_axis_deg", "cornea_offset", "cornea_tilt_deg",
                          "pupil_eccentricity", "pupil_axis_deg", "pupil_shift_per_mm"):
                tail = (VECTOR_FIELDS[f.name],) if f.name in VECTOR_FIELDS else ()
                value = np.asarray(getattr(self, f.name), dtype=float)
                if value.shape != shape + tail and value.shape == tail:
                    object.__setattr__(self, f.name, np.array(np.broadcast_to(value, shape + tail)))
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
        """A copy with some fields changed (validated again). Changing the radius or conic constant of a
        surface of revolution without naming its `_perp` twin keeps the surface of revolution."""
        for twin, source in _DEFAULT_COPIES.items():
            if source in changes and twin not in changes and np.array_equal(getattr(self, twin), getattr(self, source)):
                changes[twin] = np.array(changes[source], dtype=float, copy=True)
        return replace(self, **changes)

    def with_pupil_diameter(self, diameter: np.ndarray | float) -> EyeModel:
        """The same eyes with the stop at `diameter` (mm), its centre moved by `pupil_shift_per_mm` per mm."""
        d = np.broadcast_to(np.asarray(diameter, dtype=float), self.shape)
        change = d - 2.0 * self.pupil_radius
        return replace(self, pupil_radius=d / 2.0,
                       pupil_decentre=self.pupil_decentre + change[..., None] * self.pupil_shift_per_mm)

    # --- derived quantities -------------------------------------------------------------------
    @property
    def side_sign(self) -> np.ndarray:
        """+1 for a right eye, -1 for a left eye: multiply a right-eye x (nasal) by it."""
        return np.where(self.left, -1.0, 1.0)

    @property
    def rotationally_symmetric(self) -> np.ndarray:
        """Per eye: conic corneas of revolution about the optic axis and a circular stop (the published model)."""
        return (
            (self.anterior_radius_perp == self.anterior_radius) & (self.anterior_conic_perp == self.anterior_conic)
            & (self.posterior_radius_perp == self.posterior_radius)
            & (self.posterior_conic_perp == self.posterior_conic)
            & np.all(self.cornea_offset == 0, axis=-1) & np.all(self.cornea_tilt_deg == 0, axis=-1)
            & (self.pupil_eccentricity == 0)
        )

    @property
    def anterior_mean_radius(self) -> np.ndarray:
        """Radius of the mean power of the anterior cornea, 2 / (1/R + 1/R_perp) (mm; R_ac of a symmetric eye)."""
        r, p = self.anterior_radius, self.anterior_radius_perp
        return np.where(r == p, r, 2.0 / (1.0 / r + 1.0 / p))

    @property
    def posterior_mean_radius(self) -> np.ndarray:
        """Radius of the mean power of the posterior cornea (mm)."""
        r, p = self.posterior_radius, self.posterior_radius_perp
        return np.where(r == p, r, 2.0 / (1.0 / r + 1.0 / p))

    @property
    def stop_semi_major(self) -> np.ndarray:
        """Largest semi-axis of the stop ellipse, r (1 - e^2)^(-1/4) (mm)."""
        return self.pupil_radius / (1.0 - self.pupil_eccentricity**2) ** 0.25

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
                + ("" if e.rotationally_symmetric[i] else
                   f"; toric R_ac {e.anterior_radius[i]:.3f}/{e.anterior_radius_perp[i]:.3f} at "
                   f"{e.anterior_axis_deg[i]:.0f} deg, R_pc {e.posterior_radius[i]:.3f}/"
                   f"{e.posterior_radius_perp[i]:.3f} at {e.posterior_axis_deg[i]:.0f} deg, cornea tilt "
                   f"({e.cornea_tilt_deg[i, 0]:.1f}, {e.cornea_tilt_deg[i, 1]:.1f}) deg, stop e "
                   f"{e.pupil_eccentricity[i]:.3f}")
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
        positive = ("anterior_radius", "posterior_radius", "anterior_radius_perp", "posterior_radius_perp",
                    "cct", "acd", "pupil_radius",
                    "lens_anterior_radius", "lens_posterior_radius", "lens_thickness", "axial_length",
                    "limbus_radius")
        for name in positive:
            bad = getattr(self, name) <= 0
            if np.any(bad):
                raise ValueError(f"EyeModel.{name} must be > 0 mm; got {getattr(self, name)[bad]}")
        for name in ("anterior_conic", "posterior_conic", "anterior_conic_perp", "posterior_conic_perp"):
            bad = getattr(self, name) <= -1
            if np.any(bad):
                raise ValueError(
                    f"EyeModel.{name} = {getattr(self, name)[bad]}: the cornea must be an ellipsoid "
                    "(Q = -e^2 > -1, i.e. eccentricity |e| < 1)"
                )
        if np.any(self.lens_index <= 1):
            raise ValueError("EyeModel.lens_index must be > 1")
        if np.any((self.pupil_eccentricity < 0) | (self.pupil_eccentricity >= 1)):
            raise ValueError("EyeModel.pupil_eccentricity must be in [0, 1)")
        if np.any(np.abs(self.cornea_tilt_deg) > MAX_CORNEA_TILT_DEG):
            raise ValueError(f"EyeModel.cornea_tilt_deg must be within +-{MAX_CORNEA_TILT_DEG:g} deg")
        if np.any(self.stop_semi_major >= self.limbus_radius):
            raise ValueError("EyeModel.pupil_radius must be smaller than limbus_radius")
        if np.any(self.vitreous_length <= 0):
            raise ValueError("EyeModel: axial length leaves no room for the vitreous (AL <= CCT+ACD+T)")
