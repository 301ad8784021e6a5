"""Which added anatomy moves the study's errors (issue 13): the `--anatomy full` run broken down by addition.

Two complementary answers, both per error category of `summary.anatomy_columns` (degrees):

1. Each addition alone (`COMPONENTS`: astigmatism, pupil decentration, elliptical stop, cornea tilt): the same
   eyes run with `full_anatomy(..., only that addition)` and the same generator seed, so every addition gets
   the deviates it has in the full run (`full_anatomy` draws all of them whatever is switched on). Per category:
   mean and SD alone, the change of the mean from the paper anatomy, and the interaction
   (full - paper) - sum over additions of (alone - paper), so paper + the changes + the interaction is the
   full mean exactly (also per eye). The addition with the largest change "moves it most"; a largest change
   below `NEGLIGIBLE_DEG` is marked negligible.
2. The share of the full run's between-subject variance that each group of per-eye parameters explains:
   the per-eye error regressed (OLS with an intercept) on `GROUPS`: the study's 11 parameters (the paper's
   anatomy), the astigmatism (anterior and posterior J0, J45 and their magnitudes |J| = hypot(J0, J45), D,
   right-eye convention) and the pupil decentration (nasal and superior offset of the stop centre at the
   eye's pupil size, and its magnitude, mm). The regression's R^2 is split between the groups by their
   Shapley value (Lindeman, Merenda & Gold 1980, "LMG"; Grömping 2006, J Stat Softw 17(1)): a group's
   share is its increase of R^2 when added, averaged over every order of adding the groups, so the shares
   are non-negative and sum exactly to the R^2 of all groups together; 1 - R^2 is left unexplained (what
   the linear model misses, including the nonlinear effects). Share x variance is that group's part of the
   variance of the error between subjects. Tilt and the stop are the same in every eye, so they move the
   mean (part 1) but cannot explain any spread here.

`run_anatomy` runs the full anatomy and each addition alone (`replication.run_study`); the rest is pure numerics.
"""

from __future__ import annotations

from itertools import combinations
from math import factorial
from typing import Any

import numpy as np

from eyehil.analysis.study.replication import StudyResult, run_study
from eyehil.emulator.eye.anatomy import full_anatomy
from eyehil.emulator.eye.astigmatism import ANTERIOR_DN, POSTERIOR_DN, power_vector
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.population import study_parameters

#: The additions of `full_anatomy`, by name: (keyword of `full_anatomy`, label for tables and figures).
COMPONENTS: dict[str, str] = {"astigmatism": "astigmatism", "decentration": "pupil decentration",
                              "stop": "elliptical stop", "tilt": "cornea tilt"}
#: A change of the mean below this (deg) is within the draw-to-draw spread of one draw of 100 eyes (docs/physics.md).
NEGLIGIBLE_DEG = 0.005
#: The regressor groups of the variance shares (module docstring), in the order of the tables.
GROUPS = ("paper anatomy", "astigmatism", "pupil decentration")


def component_eyes(eyes: EyeModel, seed: int) -> dict[str, EyeModel]:
    """`eyes` with each addition of `full_anatomy` alone (keyed by `COMPONENTS`), drawn with `seed` as the full
    run (`full_anatomy(eyes, np.random.default_rng(seed))`) draws it."""
    out = {}
    for name in COMPONENTS:
        switches = {k: k == name for k in COMPONENTS}
        out[name] = full_anatomy(eyes, np.random.default_rng(seed), **switches)
    return out


def run_anatomy(eyes: EyeModel, seed: int, progress=None, **study: Any) -> tuple[StudyResult, dict[str, StudyResult]]:
    """(the full-anatomy run, {component: the run with that addition alone}) of `eyes`, drawn with `seed`;
    `study`: the keyword arguments of `run_study` (profiles, head positions, workers, ...)."""
    full = run_study(full_anatomy(eyes, np.random.default_rng(seed)), progress=progress, **study)
    alone = {name: run_study(e, progress=progress, **study) for name, e in component_eyes(eyes, seed).items()}
    return full, alone


def added_parameters(eyes: EyeModel) -> dict[str, dict[str, np.ndarray]]:
    """Per group of `GROUPS`, the per-eye parameters (name -> (E,)) of `eyes` (anatomy as right eyes)."""
    e = eyes.as_batch()
    _, aj0, aj45 = power_vector(e.anterior_radius, e.anterior_radius_perp, e.anterior_axis_deg, ANTERIOR_DN)
    _, pj0, pj45 = power_vector(e.posterior_radius, e.posterior_radius_perp, e.posterior_axis_deg, POSTERIOR_DN)
    dx, dy = e.pupil_decentre[:, 0], e.pupil_decentre[:, 1]
    return {
        "paper anatomy": study_parameters(e),
        "astigmatism": {"J0 ant (D)": aj0, "J45 ant (D)": aj45, "|J| ant (D)": np.hypot(aj0, aj45),
                        "J0 post (D)": pj0, "J45 post (D)": pj45, "|J| post (D)": np.hypot(pj0, pj45)},
        "pupil decentration": {"nasal (mm)": dx, "superior (mm)": dy, "|decentre| (mm)": np.hypot(dx, dy)},
    }


def r_squared(y: np.ndarray, X: np.ndarray) -> float:
    """R^2 of the OLS of y (n,) on an intercept and the columns of X (n, k); 0 for k = 0."""
    if X.shape[1] == 0:
        return 0.0
    design = np.column_stack([np.ones(len(y)), X])
    residual = y - design @ np.linalg.lstsq(design, y, rcond=None)[0]
    centred = y - y.mean()
    return float(1.0 - residual @ residual / (centred @ centred))


def shapley_shares(y: np.ndarray, groups: dict[str, np.ndarray]) -> dict[str, float]:
    """Shapley (LMG) split of the R^2 of y on all `groups` (name -> (n, k_g) columns): name -> share of R^2.

    share_g = sum over subsets S of the other groups of |S|! (G - |S| - 1)! / G! (R^2(S + g) - R^2(S)); the
    shares sum to R^2(all groups) exactly (up to rounding)."""
    names = list(groups)
    g = len(names)
    y = np.asarray(y, dtype=float)
    cache: dict[frozenset[str], float] = {}

    def r2(subset: frozenset[str]) -> float:
        if subset not in cache:
            cols = [groups[n] for n in names if n in subset]
            cache[subset] = r_squared(y, np.column_stack(cols) if cols else np.empty((len(y), 0)))
        return cache[subset]

    shares = {}
    for name in names:
        others = [n for n in names if n != name]
        total = 0.0
        for k in range(g):
            weight = factorial(k) * factorial(g - k - 1) / factorial(g)
            for subset in combinations(others, k):
                s = frozenset(subset)
                total += weight * (r2(s | {name}) - r2(s))
        shares[name] = total
    return shares


def variance_shares(y: np.ndarray, parameters: dict[str, dict[str, np.ndarray]]) -> dict[str, Any]:
    """The Shapley split of the variance of the per-eye error `y` (module docstring, part 2) on the groups of
    `added_parameters`: {variance, r_squared, shares: {group: share of the variance}, unexplained}; with too few
    finite eyes for the regression ({"skipped": reason})."""
    ok = np.isfinite(y)
    k = sum(len(p) for p in parameters.values())
    if ok.sum() <= k + 2:
        return {"skipped": f"not enough eyes: {int(ok.sum())} eyes for {k} parameters (needs at least {k + 3})"}
    groups = {name: np.column_stack(list(p.values()))[ok] for name, p in parameters.items()}
    shares = shapley_shares(y[ok], groups)
    total = r_squared(y[ok], np.column_stack(list(groups.values())))
    return {"variance": float(np.var(y[ok], ddof=1)), "r_squared": total, "shares": shares,
            "unexplained": 1.0 - total, "eyes": int(ok.sum())}


def component_changes(paper: np.ndarray, alone: dict[str, np.ndarray], full: np.ndarray) -> dict[str, Any]:
    """Means and SDs (finite eyes of every run) of the paper, each addition alone and the full anatomy, the change
    of the mean by each addition alone, and the interaction (module docstring, part 1)."""
    runs = {"paper": paper, **alone, "full": full}
    ok = np.all([np.isfinite(v) for v in runs.values()], axis=0)
    stat = {k: {"mean": float(np.mean(v[ok])), "sd": float(np.std(v[ok], ddof=1)) if ok.sum() > 1 else float("nan")}
            for k, v in runs.items()}
    change = {k: stat[k]["mean"] - stat["paper"]["mean"] for k in alone}
    total = stat["full"]["mean"] - stat["paper"]["mean"]
    return {"runs": stat, "change": change, "total_change": total, "interaction": total - sum(change.values()),
            "eyes": int(ok.sum())}


def breakdown(paper: dict[str, np.ndarray], alone: dict[str, dict[str, np.ndarray]], full: dict[str, np.ndarray],
              full_eyes: EyeModel) -> dict[str, Any]:
    """Per error category (keys of `paper`; each a per-eye array): the component changes and the variance shares
    of the full run. `alone`: {component: {category: per-eye}}; `full_eyes`: the full run's eyes."""
    parameters = added_parameters(full_eyes)
    out = {}
    for col in paper:
        changes = component_changes(paper[col], {c: alone[c][col] for c in alone}, full[col])
        largest = max(changes["change"], key=lambda c: abs(changes["change"][c]))
        out[col] = changes | {"variance": variance_shares(full[col], parameters), "largest_change": largest,
                              "negligible": abs(changes["change"][largest]) < NEGLIGIBLE_DEG}
    return out
