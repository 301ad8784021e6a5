"""The detector's tuning, in px and DN of the 8-bit image (see `detector` and `glints`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DetectorSettings:
    """Tuning, in px and DN of the 8-bit image (see the module docstrings)."""

    min_pupil_diameter_px: float = 12.0
    max_pupil_diameter_px: float = 120.0
    coarse_factor: int = 4
    dark_margin_dn: float = 20.0
    min_contrast_dn: float = 20.0
    glint_level: float = 0.85  # of saturation
    saturation_dn: float = 255.0
    glint_search: float = 2.5  # pupil radii
    glint_max_area_px: int = 200
    glint_guard_px: int = 3
    inlier_px: float = 0.6
    refits: int = 3
    min_edge_points: int = 12
    min_support: float = 0.5
    min_axis_ratio: float = 0.5
