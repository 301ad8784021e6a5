"""Features: what the forward model computes, arrays shaped (E eyes, S sides, H head positions, T targets, ...).

Image quantities in pixels (OpenCV convention: origin at the top-left pixel centre, x right, y down);
3-D ground truth in the scene frame (mm); angles in degrees. The pupil ellipse angle is that of the
major axis from image +x toward image +y, in [0, 180); axes are full lengths (major, minor).
A feature that could not be computed is NaN and its validity flag False; `valid` is the conjunction
of fixation, pupil and every glint. Features that fall off the sensor keep their extrapolated pixels
(as gkaModelEye and the published study did); `in_image` flags them and `visible` excludes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

# name -> (trailing shape key, dtype); keys: "" scalar, "2", "3", "N2" pupil points, "N" , "L2", "L"
ARRAYS: dict[str, tuple[str, type]] = {
    "pupil_centre_px": ("2", float), "pupil_axes_px": ("2", float), "pupil_angle_deg": ("", float),
    "pupil_valid": ("", bool), "pupil_points_px": ("N2", float), "pupil_points_valid": ("N", bool),
    "pupil_residual_mm": ("", float), "glint_px": ("L2", float), "glint_valid": ("L", bool),
    "glint_residual_mm": ("L", float), "azimuth_deg": ("", float), "elevation_deg": ("", float),
    "torsion_deg": ("", float), "in_image": ("", bool), "fixation_residual_mm": ("", float),
    "fixation_valid": ("", bool),
    "cornea_centre": ("3", float), "pupil_centre": ("3", float), "apex": ("3", float), "fovea": ("3", float),
    "los_origin": ("3", float), "optic_axis": ("3", float), "visual_axis": ("3", float),
}


@dataclass(eq=False)
class Features:
    """See the module docstring. `targets` is (T, 3) in the scene frame, or None for explicit poses."""

    scene: str
    sides: tuple[str, ...]
    head_positions: tuple[Any, ...]
    leds: np.ndarray
    targets: np.ndarray | None
    media: str
    arrays: dict[str, np.ndarray] = field(default_factory=dict)

    def __getattr__(self, name: str) -> np.ndarray:
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        raise AttributeError(name)

    @property
    def shape(self) -> tuple[int, ...]:
        """(E, S, H, T)."""
        return self.arrays["pupil_valid"].shape

    @property
    def valid(self) -> np.ndarray:
        return self.fixation_valid & self.pupil_valid & np.all(self.glint_valid, axis=-1)

    @property
    def visible(self) -> np.ndarray:
        """Valid and on the sensor: what a real camera of this scene would deliver."""
        return self.valid & self.in_image

    @property
    def pupil_glint_px(self) -> np.ndarray:
        """Pupil centre minus glint centre, (E, S, H, T, L, 2) px."""
        return self.pupil_centre_px[..., None, :] - self.glint_px

    def counts(self) -> dict[str, int]:
        """How many fixations, and how many failed each stage."""
        return {
            "fixations": int(np.prod(self.shape)),
            "fixation_failed": int(np.count_nonzero(~self.fixation_valid)),
            "pupil_failed": int(np.count_nonzero(~self.pupil_valid)),
            "pupil_points_blocked": int(np.count_nonzero(~self.pupil_points_valid)),
            "glints_invalid": int(np.count_nonzero(~self.glint_valid)),
            "off_sensor": int(np.count_nonzero(self.valid & ~self.in_image)),
            "valid": int(np.count_nonzero(self.valid)),
        }

    def save(self, path: str | Path) -> Path:
        """Write every array and the metadata to a compressed .npz file."""
        path = Path(path)
        meta = {"scene": self.scene, "sides": list(self.sides), "media": self.media,
                "head_positions": [getattr(h, "name", str(h)) for h in self.head_positions]}
        extra = {"targets": self.targets} if self.targets is not None else {}
        np.savez_compressed(path, meta=np.array(repr(meta)), leds=self.leds, **extra, **self.arrays)
        return path if path.suffix == ".npz" else path.with_suffix(path.suffix + ".npz")


def empty_features(n_eyes: int, scene: Any, heads: tuple, n_targets: int, n_points: int,
                   targets: np.ndarray | None, media: str) -> Features:
    """Features filled with NaN / False, to be written chunk by chunk."""
    base = (n_eyes, len(scene.sides), len(heads), n_targets)
    n_leds = len(scene.leds)
    tails = {"": (), "2": (2,), "3": (3,), "N2": (n_points, 2), "N": (n_points,), "L2": (n_leds, 2), "L": (n_leds,)}
    arrays = {
        name: (np.zeros if dtype is bool else lambda s: np.full(s, np.nan))(base + tails[key])
        for name, (key, dtype) in ARRAYS.items()
    }
    for name, (_, dtype) in ARRAYS.items():
        if dtype is bool:
            arrays[name] = arrays[name].astype(bool)
    return Features(scene=scene.name, sides=tuple(scene.sides), head_positions=heads, leds=np.array(scene.leds),
                    targets=None if targets is None else np.array(targets), media=media, arrays=arrays)


__all__ = ["ARRAYS", "Features", "empty_features"]
