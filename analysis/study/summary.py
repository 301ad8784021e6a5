"""The published statistics of a replication run (`StudyResult` -> the `summary.json` dictionary).

Keys: `table4` {parameter: [mean, sd]}; `guestrin` {H1, H2: {mean, sd, skewness}, welch_t, f_test:
{H1|H2: {statistic, df, p}}}; `blignaut` {by_model: {model: {configuration: mean}}, best_function:
{configuration: {model, mean}}, one_sample_t: {configuration: {statistic, df, p}}}; `sensitivity`
{H1, H2, C5 ... C135: {coefficients: {parameter: {coef, p}}, significant: [...], reduced: {parameter:
coef}, r_squared, univariate: {parameter: {coef, p, r_squared}}, significant_univariate: [...]}} with
coefficients in degrees per SD of the z-scored parameter (the full fit on all 11 parameters, the paper's
text; `r_squared` is that of the refit on the significant ones, as the paper reports; `univariate` the
one-parameter fits the study's code ran); `guestrin_compare` {profile, H1, H2: {mean, sd, skewness},
sensitivity: {H1, H2: as above}} for the comparison profile on the same features (None without one);
`anatomy` (only with `--anatomy full`, `anatomy_summary`) {category: {paper, full: {mean, sd, significant}}} for
the Guestrin H1/H2 of each profile and the Blignaut best-function errors, the same eyes with paper and full anatomy;
`anatomy_breakdown` (with `--anatomy full`, `anatomy_breakdown`) {category: {runs: {paper, astigmatism, decentration,
stop, tilt, full: {mean, sd}}, change: {addition: change of the mean alone}, total_change, interaction,
largest_change, variance: {variance, r_squared, shares: {group: share}, unexplained, eyes}}}
(`eyehil.analysis.study.breakdown`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from eyehil.analysis.study import stats
from eyehil.analysis.study.breakdown import breakdown
from eyehil.analysis.study.published import CONFIGURATIONS, blignaut_real, guestrin_real_deg
from eyehil.analysis.study.replication import StudyResult
from eyehil.drivers.gaze.forms import MODELS
from eyehil.emulator.eye.population import parameter_table, study_parameters


def best_functions(errors: np.ndarray) -> dict[str, dict[str, float]]:
    """Per configuration, the model (1-based) with the lowest mean error over the eyes."""
    means = _mean_over_eyes(errors)
    out = {}
    for c, name in enumerate(CONFIGURATIONS):
        m = int(np.nanargmin(means[:, c]))
        out[name] = {"model": sorted(MODELS)[m], "mean": float(means[m, c])}
    return out


def best_function_errors(errors: np.ndarray) -> dict[str, np.ndarray]:
    """Per configuration, each eye's error under that configuration's best function."""
    best = best_functions(errors)
    return {name: errors[:, sorted(MODELS).index(best[name]["model"]), c] for c, name in enumerate(CONFIGURATIONS)}


def _mean_over_eyes(errors: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        counts = np.sum(np.isfinite(errors), axis=0)
        return np.where(counts > 0, np.nansum(errors, axis=0) / np.maximum(counts, 1), np.nan)


def _test(t: stats.TTest | stats.FTest) -> dict[str, Any]:
    if isinstance(t, stats.FTest):
        return {"statistic": float(t.F), "df": [float(t.df1), float(t.df2)], "p": float(t.p)}
    return {"statistic": float(t.t), "df": float(t.df), "p": float(t.p)}


def guestrin_summary(result: StudyResult) -> dict[str, Any]:
    real = guestrin_real_deg()
    failures = [f for f in result.failures if "blignaut" not in f]
    out: dict[str, Any] = {"profile": result.settings.get("guestrin_profile"), "failures": failures}
    for key, values in (("H1", result.h1), ("H2", result.h2)):
        s = stats.summarise(values[np.isfinite(values)])
        out[key] = {"mean": s.mean, "sd": s.sd, "skewness": s.skewness, "n": s.n}
    out["welch_t"] = {k: _test(stats.welch_t_test(v[np.isfinite(v)], real[k])) for k, v in
                      (("H1", result.h1), ("H2", result.h2))}
    out["f_test"] = {k: _test(stats.f_test_variances(v[np.isfinite(v)], real[k])) for k, v in
                     (("H1", result.h1), ("H2", result.h2))}
    out["real"] = {k: {"mean": float(v.mean()), "sd": float(v.std(ddof=1)), "n": int(v.size)} for k, v in real.items()}
    return out


def blignaut_summary(result: StudyResult) -> dict[str, Any]:
    means = _mean_over_eyes(result.blignaut_errors)
    by_model = {str(k): {c: (None if np.isnan(means[m, i]) else float(means[m, i]))
                         for i, c in enumerate(CONFIGURATIONS)} for m, k in enumerate(sorted(MODELS))}
    real = blignaut_real()
    per_eye = best_function_errors(result.blignaut_errors)
    return {
        "by_model": by_model,
        "best_function": best_functions(result.blignaut_errors),
        "one_sample_t": {c: _test(stats.one_sample_t_test(v[np.isfinite(v)], real["best_error"][c]))
                         for c, v in per_eye.items()},
        "eyes_without_error": {c: int(np.count_nonzero(~np.isfinite(v))) for c, v in per_eye.items()},
        "real_best_function": {c: {"model": real["best_model"][c], "mean": real["best_error"][c]}
                               for c in CONFIGURATIONS},
        "failed_fits": [f for f in result.failures if "blignaut" in f],
    }


def error_columns(result: StudyResult) -> dict[str, np.ndarray]:
    """The 8 error categories of the sensitivity analysis, per eye."""
    return {"H1": result.h1, "H2": result.h2, **best_function_errors(result.blignaut_errors)}


def sensitivity_summary(result: StudyResult, columns: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    """Multivariate and univariate sensitivity of each error column (default: the 8 of `error_columns`)."""
    params = study_parameters(result.eyes)
    names = list(params)
    X = np.column_stack([params[k] for k in names])
    out: dict[str, Any] = {}
    for column, y in (columns if columns is not None else error_columns(result)).items():
        ok = np.isfinite(y)
        if ok.sum() <= len(names) + 2:
            out[column] = {"coefficients": {}, "significant": [], "reduced": {}, "r_squared": float("nan"),
                           "r_squared_all": float("nan"), "univariate": {}, "significant_univariate": [],
                           "skipped": f"{int(ok.sum())} eyes: the regression on {len(names)} parameters needs more"}
            continue
        s = stats.sensitivity_regression(X[ok], y[ok], names)
        full = {n: {"coef": float(s.full.coef[i + 1]), "p": float(s.full.p[i + 1])} for i, n in enumerate(names)}
        reduced = {n: float(s.reduced.coefficient(n)) for n in s.significant}
        strongest = sorted(s.significant, key=lambda n: -abs(full[n]["coef"]))
        uni = {n: {"coef": float(f.coef[1]), "p": float(f.p[1]), "r_squared": float(f.r_squared)}
               for n, f in stats.univariate_regressions(X[ok], y[ok], names).items()}
        uni_sig = sorted((n for n in names if uni[n]["p"] < s.alpha), key=lambda n: -abs(uni[n]["coef"]))
        out[column] = {"coefficients": full, "significant": strongest, "reduced": reduced,
                       "r_squared": float(s.reduced.r_squared), "r_squared_all": float(s.full.r_squared),
                       "univariate": uni, "significant_univariate": uni_sig}
    return out


def compare_summary(result: StudyResult) -> dict[str, Any] | None:
    """The comparison profile's H1/H2 statistics and sensitivity (same features as the main profile)."""
    name = result.settings.get("compare_profile")
    if not name or name not in result.profiles or name == result.settings.get("guestrin_profile"):
        return None
    run = result.profiles[name]
    out: dict[str, Any] = {"profile": name}
    for key, values in (("H1", run["h1"]), ("H2", run["h2"])):
        s = stats.summarise(values[np.isfinite(values)])
        out[key] = {"mean": s.mean, "sd": s.sd, "skewness": s.skewness, "n": s.n}
    out["sensitivity"] = sensitivity_summary(result, {"H1": run["h1"], "H2": run["h2"]})
    return out


def anatomy_columns(result: StudyResult) -> dict[str, np.ndarray]:
    """The error categories compared between anatomies: H1/H2 of every profile, then the Blignaut best functions."""
    cols = {f"{k} {name}": run[k.lower()] for name, run in result.profiles.items() for k in ("H1", "H2")}
    return cols | best_function_errors(result.blignaut_errors)


def anatomy_summary(paper: StudyResult, full: StudyResult) -> dict[str, Any]:
    """Per error category: mean, SD and the significant parameters (multivariate, strongest first) of the same
    eyes with the paper's anatomy and with `eyehil.emulator.eye.anatomy.full_anatomy`."""
    out: dict[str, Any] = {}
    for name, result in (("paper", paper), ("full", full)):
        columns = anatomy_columns(result)
        sens = sensitivity_summary(result, columns)
        for col, y in columns.items():
            s = stats.summarise(y[np.isfinite(y)])
            out.setdefault(col, {})[name] = {"mean": s.mean, "sd": s.sd, "significant": sens[col]["significant"]}
    return out


def anatomy_breakdown(paper: StudyResult, alone: dict[str, StudyResult], full: StudyResult) -> dict[str, Any]:
    """Which addition moves each error category (`breakdown.breakdown`): the same eyes with the paper anatomy, each
    addition alone and the full anatomy."""
    return breakdown(anatomy_columns(paper), {k: anatomy_columns(r) for k, r in alone.items()},
                     anatomy_columns(full), full.eyes)


def summarise_study(result: StudyResult) -> dict[str, Any]:
    """Everything `summary.json` holds (module docstring)."""
    table = {k: [float(m), float(s)] for k, (m, s) in parameter_table(result.eyes).items()}
    return {
        "table4": table,
        "guestrin": guestrin_summary(result),
        "blignaut": blignaut_summary(result),
        "sensitivity": sensitivity_summary(result),
        "guestrin_compare": compare_summary(result),
        "counts": result.counts,
        "settings": result.settings,
    }
