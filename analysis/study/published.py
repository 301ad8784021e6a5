"""The published figures the replication is judged against (`analysis/study/data/published_results.json`).

Sources: Guestrin & Eizenman 2006 (real subjects), Blignaut 2014 (real participants and the
calibration sets), Fischer et al. 2023 (the published simulation). Angles in degrees.
"""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

CONFIGURATIONS = ("C5", "C9", "C14", "C18", "C23", "C135")


@cache
def published() -> dict[str, Any]:
    """The whole file, parsed."""
    return json.loads((resources.files("eyehil.analysis") / "data" / "published_results.json").read_text("utf-8"))


def guestrin_real_deg() -> dict[str, np.ndarray]:
    """Per-subject mean errors of Guestrin 2006's 4 subjects, degrees: atan(mm / 650)."""
    g = published()["guestrin2006_real"]
    d = g["screen_distance_mm"]
    return {"H1": np.degrees(np.arctan(np.array(g["central_head_position_error_mm"]) / d)),
            "H2": np.degrees(np.arctan(np.array(g["moved_head_positions_error_mm"]) / d))}


def calibration_sets() -> dict[str, np.ndarray]:
    """0-based target indices of each Blignaut calibration configuration (C135 = all 135)."""
    sets = {k: np.array(v) - 1 for k, v in published()["blignaut2014_calibration_sets"]["index_1_based"].items()}
    sets["C135"] = np.arange(135)
    return {k: sets[k] for k in CONFIGURATIONS}


def blignaut_real() -> dict[str, Any]:
    """Real best-function errors and models per configuration, and the model x configuration table."""
    b = published()["blignaut2014_real"]
    return {"best_error": dict(zip(CONFIGURATIONS, b["best_function_error_deg"], strict=True)),
            "best_model": dict(zip(CONFIGURATIONS, b["best_function_model"], strict=True)),
            "by_model": np.array(b["mean_error_deg_by_model"]), "participants": b["participants"]}


def fischer_simulated() -> dict[str, Any]:
    """The published simulation's figures."""
    return published()["fischer2023_simulated"]
