"""Statistics of the replication study (pure numerics; Fischer et al. 2023, "Analyses").

- Welch's t-test of two means (unequal variances; Welch-Satterthwaite degrees of freedom
  df = (v1 + v2)^2 / (v1^2/(n1 - 1) + v2^2/(n2 - 1)), v = s^2/n, s the ddof=1 SD), two-sided.
- Two-sided F-test of two variances: F = s1^2 / s2^2 with df (n1 - 1, n2 - 1),
  p = 2 min(P(F' <= F), P(F' >= F)), capped at 1.
- One-sample t-test: t = (mean - mu) / (s / sqrt(n)), df = n - 1, two-sided.
- Skewness: the biased (population) moment coefficient g1 = m3 / m2^(3/2) with central moments
  m_k = mean((x - mean)^k); Matlab's `skewness(x)` default and scipy.stats.skew(bias=True).
  bias=False gives the adjusted G1 = g1 sqrt(n (n - 1)) / (n - 2).
- Sensitivity regression: the parameter columns are z-scored with the sample SD (ddof=1, as
  Matlab's `zscore`), an error column is regressed on them with an intercept by ordinary least
  squares (numpy: coefficients by the pseudo-inverse, standard errors sqrt(diag(s^2 (X'X)^+)) with
  s^2 = SS_res / (n - k), as statsmodels OLS computes them; tests/test_stats.py compares the two), p-values
  from two-sided t-tests of each coefficient; the model is refit
  on the parameters with p < alpha (0.05). Coefficients are in units of the error per SD of the
  parameter. R^2 = 1 - SS_res / SS_tot.
- Univariate sensitivity: each z-scored parameter alone, error = b0 + b1 z + e (OLS), with its own
  two-sided p and R^2: the per-parameter fits the study's code ran (the multivariate regression
  above is the paper's text).
- Partial regression (added-variable) points for one column of a design (Velleman & Welsch 1981):
  the residuals of y and of that column, each regressed on the other columns; their least-squares
  slope through the origin equals the column's coefficient in the full fit (Frisch-Waugh-Lovell).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class TTest:
    """A two-sided t-test: statistic t, degrees of freedom df, p-value p."""

    t: float
    df: float
    p: float


@dataclass(frozen=True)
class FTest:
    """A two-sided variance-ratio test: F = var1/var2 with (df1, df2), p-value p."""

    F: float
    df1: float
    df2: float
    p: float


def _sample(a: Sequence[float] | np.ndarray, minimum: int = 2) -> np.ndarray:
    x = np.asarray(a, dtype=float).ravel()
    if x.size < minimum or not np.all(np.isfinite(x)):
        bad = int(np.count_nonzero(~np.isfinite(x)))
        raise ValueError(f"need at least {minimum} values, all finite; got {x.size}, {bad} of them not finite")
    return x


def welch_t_test_from_stats(mean1: float, sd1: float, n1: int, mean2: float, sd2: float, n2: int) -> TTest:
    """Welch's t-test of mean1 - mean2 from summary statistics (SDs with ddof=1)."""
    v1, v2 = sd1**2 / n1, sd2**2 / n2
    df = (v1 + v2) ** 2 / (v1**2 / (n1 - 1) + v2**2 / (n2 - 1))
    res = stats.ttest_ind_from_stats(mean1, sd1, n1, mean2, sd2, n2, equal_var=False)
    return TTest(float(res.statistic), float(df), float(res.pvalue))


def welch_t_test(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> TTest:
    """Welch's t-test of mean(a) - mean(b) from samples."""
    x, y = _sample(a), _sample(b)
    return welch_t_test_from_stats(x.mean(), x.std(ddof=1), x.size, y.mean(), y.std(ddof=1), y.size)


def f_test_from_stats(sd1: float, n1: int, sd2: float, n2: int) -> FTest:
    """Two-sided F-test of sd1^2 / sd2^2 (SDs with ddof=1) with df (n1 - 1, n2 - 1)."""
    F, df1, df2 = sd1**2 / sd2**2, n1 - 1, n2 - 1
    p = 2.0 * min(stats.f.cdf(F, df1, df2), stats.f.sf(F, df1, df2))
    return FTest(float(F), float(df1), float(df2), float(min(p, 1.0)))


def f_test_variances(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray) -> FTest:
    """Two-sided F-test of var(a) / var(b) from samples."""
    x, y = _sample(a), _sample(b)
    return f_test_from_stats(x.std(ddof=1), x.size, y.std(ddof=1), y.size)


def one_sample_t_test(a: Sequence[float] | np.ndarray, popmean: float) -> TTest:
    """Two-sided one-sample t-test of mean(a) against popmean, df = n - 1."""
    x = _sample(a)
    res = stats.ttest_1samp(x, popmean)
    return TTest(float(res.statistic), float(x.size - 1), float(res.pvalue))


def skewness(a: Sequence[float] | np.ndarray, bias: bool = True) -> float:
    """Sample skewness: biased g1 = m3 / m2^1.5 (Matlab default) or, with bias=False, adjusted G1."""
    return float(stats.skew(_sample(a, 3), bias=bias))


@dataclass(frozen=True)
class Summary:
    """n, mean, SD (ddof=1) and biased skewness g1 of a sample."""

    n: int
    mean: float
    sd: float
    skewness: float


def summarise(a: Sequence[float] | np.ndarray) -> Summary:
    """The summary the study reports per error column."""
    x = _sample(a, 3)
    return Summary(x.size, float(x.mean()), float(x.std(ddof=1)), skewness(x))


def zscore_columns(X: np.ndarray) -> np.ndarray:
    """(X - column mean) / column SD with ddof=1 (Matlab `zscore`); ValueError for a constant column."""
    X = np.asarray(X, dtype=float)
    sd = X.std(axis=0, ddof=1)
    if X.ndim != 2 or not np.all(np.isfinite(X)) or np.any(sd == 0):
        raise ValueError("X must be a finite (n, h) array without constant columns")
    return (X - X.mean(axis=0)) / sd


@dataclass(frozen=True)
class OLSFit:
    """An ordinary least-squares fit; arrays follow `names` ("const" first).

    coef, se (standard errors), t, p (two-sided); r_squared; df_resid = n - number of coefficients.
    """

    names: tuple[str, ...]
    coef: np.ndarray
    se: np.ndarray
    t: np.ndarray
    p: np.ndarray
    r_squared: float
    df_resid: float

    def coefficient(self, name: str) -> float:
        """The coefficient of `name`."""
        return float(self.coef[self.names.index(name)])


def ols(y: np.ndarray, X: np.ndarray, names: Sequence[str]) -> OLSFit:
    """OLS of y (n,) on an intercept plus the columns of X (n, h) named `names`."""
    X = np.asarray(X, dtype=float)
    if X.shape != (len(y), len(names)):
        raise ValueError(f"X must have shape ({len(y)}, {len(names)}), got {X.shape}")
    y = np.asarray(y, dtype=float)
    design = np.column_stack([np.ones(len(y)), X])
    pinv = np.linalg.pinv(design)
    coef = pinv @ y
    residual = y - design @ coef
    df_resid = float(len(y) - np.linalg.matrix_rank(design))
    sigma2 = float(residual @ residual) / df_resid
    se = np.sqrt(sigma2 * np.diag(pinv @ pinv.T))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = coef / se
    p = 2.0 * stats.t.sf(np.abs(t), df_resid)
    centred = y - y.mean()
    r2 = 1.0 - float(residual @ residual) / float(centred @ centred) if X.shape[1] else 0.0
    return OLSFit(("const", *names), coef, se, t, p, r2, df_resid)


@dataclass(frozen=True)
class Sensitivity:
    """The study's sensitivity analysis of one error column.

    `full`: OLS on all z-scored parameters; `significant`: parameters with p < alpha in `full`;
    `reduced`: the refit on those (intercept only when none is significant). Coefficients are in
    units of the error per SD of the parameter.
    """

    full: OLSFit
    significant: tuple[str, ...]
    reduced: OLSFit
    alpha: float


def sensitivity_regression(
    params: np.ndarray, error: np.ndarray, names: Sequence[str], alpha: float = 0.05
) -> Sensitivity:
    """Regress `error` (n,) on the z-scored (ddof=1) parameter columns `params` (n, h); refit on p < alpha."""
    y = _sample(error, 3)
    Z = zscore_columns(params)
    if Z.shape != (y.size, len(names)):
        raise ValueError(f"params must have shape ({y.size}, {len(names)}), got {Z.shape}")
    full = ols(y, Z, tuple(names))
    keep = [i for i, name in enumerate(names) if full.p[i + 1] < alpha]
    reduced = ols(y, Z[:, keep], tuple(names[i] for i in keep))
    return Sensitivity(full, tuple(names[i] for i in keep), reduced, alpha)


def univariate_regressions(params: np.ndarray, error: np.ndarray, names: Sequence[str]) -> dict[str, OLSFit]:
    """One OLS of `error` (n,) per z-scored (ddof=1) parameter column of `params` (n, h), by name."""
    y = _sample(error, 3)
    Z = zscore_columns(params)
    if Z.shape != (y.size, len(names)):
        raise ValueError(f"params must have shape ({y.size}, {len(names)}), got {Z.shape}")
    return {name: ols(y, Z[:, [i]], (name,)) for i, name in enumerate(names)}


@dataclass(frozen=True)
class PartialRegression:
    """Added-variable plot data: x = residual of the column, y = residual of the response; slope = coef."""

    x: np.ndarray
    y: np.ndarray
    slope: float


def partial_regression(design: np.ndarray, y: np.ndarray, column: int) -> PartialRegression:
    """Partial regression points of column `column` of `design` (n, k) (include the constant yourself).

    For the study's plot of the constant term, pass the design [1, Z_significant] and column 0.
    """
    design = np.asarray(design, dtype=float)
    y = np.asarray(y, dtype=float)
    others = np.delete(design, column, axis=1)

    def residual(v: np.ndarray) -> np.ndarray:
        return v - others @ np.linalg.lstsq(others, v, rcond=None)[0] if others.shape[1] else v

    rx, ry = residual(design[:, column]), residual(y)
    return PartialRegression(rx, ry, float(rx @ ry / (rx @ rx)))
