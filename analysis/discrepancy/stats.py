"""Where a simulation and measured data disagree: tests of the mean and the spread per condition, and the gap
measure D (a sum of squared normal scores, read as a chi-square).

Per condition c (degrees), the compared quantity is the condition itself, or, for paired measured data
and a condition with a reference r (H2 and head:* refer to H1), the within-subject difference c - r,
computed the same way for every simulated eye and every measured subject. Then:

- **mean**: Welch's t of the simulated mean against the measured mean (Welch-Satterthwaite df), from
  per-subject values or a summary with an SD; a summary without an SD (Blignaut 2014's published means)
  gets the one-sample t of the simulated eyes against the measured mean, df = n - 1.
- **spread** (per-subject values or a summary with an SD): the log ratio of the SDs,
  z_s = ln(s_sim / s_meas) / se, se^2 = sum over both samples of (2 / (n - 1) + g2 / n) / 4, with g2 the
  pooled excess kurtosis of the mean-centred samples, floored at 0 (Bonett 2006, Applied Psychological
  Measurement 30(5):432-439: the kurtosis-robust standard error of a log SD ratio). Without a measured
  SD there is no spread term.

The normal score of the mean term is z_m = Phi^-1(F_t(t; df)) (the t's own tail turned into a normal
deviate, so four subjects' heavy-tailed t does not dominate D); for huge t whose tail underflows, z_m = t.
The gap measure is D = sum_c (z_m^2 + z_s^2): under "no gap" each term is about chi-square(1), and a
change of the model that widens the simulated spread to shrink every t (added noise) pays in z_s what it
saves in z_m. Conditions share subjects, so the terms are correlated and D is a chi-square only roughly.

**Significance** (`tests=True`, the find and show steps): where both samples are per-subject values whose SDs reach
the resolution (below), p-values come from a Monte Carlo permutation test (`PERMUTATIONS` random relabellings of the
pooled values, seeded by the condition name; p = (1 + #{|stat*| >= |stat|}) / (B + 1)), of the Welch t for the mean
and, on the mean-centred values, of ln(s1 / s2) for the spread. Under "no gap" (the two samples from one
distribution) this is exact up to the Monte Carlo error, whatever the skew of the errors and however few the
subjects, which the t-distribution is not (four skewed values gave spurious gaps). Otherwise the parametric p of the
statistic above. All mean and spread p-values of a comparison form one family, Holm adjusted (`holm`); a gap is
significant when its p_holm < alpha. `tests=False` (every point of a search) skips the permutations and keeps the
parametric p.

**Resolution** (`SD_FLOOR`, 1e-4 of each quantity's unit): an SD below it is taken as it, in D and in the
tests. A permutation statistic is scale-free: relabelling the pooled values resolves a difference however far
below the resolution it lies. Noise-free feature conditions are so precise (the paired contrast of the pupil axis
ratio between two head positions varies by 1e-5 across eyes) that a permutation test would call a difference of a
few 1e-5 in the ratio a gap. D does not see such a difference, and no tracker resolves one. So where either
sample's SD is below the resolution, the condition is tested by the parametric p of its floored statistics
(`test` "welch (resolution)"), the same statistics D uses.

**Goodness of fit** (`permutation_gof`): the terms of D are correlated (conditions share subjects; the
same quantity at several head positions), so D is not a chi-square with one degree of freedom per term.
Where every measured condition has per-subject values, the null distribution of D itself is drawn by
relabelling whole units (a simulated eye or a measured subject with all its conditions together) between
the two samples (`GOF_PERMUTATIONS` relabellings): p = (1 + #{D* >= D}) / (B + 1). The correlations are
kept, so no independence is assumed; the fitted parameters make the observed D slightly small, so the
test is conservative toward "fits". Otherwise the chi-square reading (`Comparison.gof_p`).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy import stats as sps

from eyehil.analysis.discrepancy.data import Measured, MeasuredCondition
from eyehil.analysis.study.stats import welch_t_test_from_stats

#: The resolution of every compared quantity, in its own unit (deg of gaze error, px of a feature, or a ratio):
#: an SD below it is taken as it, in D and in the tests alike (module docstring, "Resolution").
SD_FLOOR = 1e-4
PERMUTATIONS = 4000
GOF_PERMUTATIONS = 200
BOOTSTRAP = 200  # resamples of `term_covariance`


@dataclass(frozen=True)
class ConditionGap:
    """One condition: what was compared, both means and SDs (deg), the mean and spread tests."""

    condition: str
    compared: str
    test: str
    simulated: float
    simulated_sd: float
    n_simulated: int
    measured: float
    measured_sd: float | None
    n_measured: int
    t: float
    df: float
    p: float
    z: float = float("nan")  # the normal score of the mean term
    z_spread: float = float("nan")  # ln(s_sim / s_meas) / se, NaN without a measured SD
    p_spread: float = float("nan")
    p_holm: float = float("nan")
    p_spread_holm: float = float("nan")

    @property
    def difference(self) -> float:
        """Simulated minus measured mean (deg)."""
        return self.simulated - self.measured

    @property
    def ci95(self) -> float:
        """Half-width of the 95 % confidence interval of the difference (deg)."""
        se = abs(self.difference / self.t) if self.t else 0.0
        return float(sps.t.ppf(0.975, max(self.df, 1.0)) * se)

    @property
    def term(self) -> float:
        """This condition's share of D: z^2 + z_spread^2."""
        return float(self.z**2 + (0.0 if np.isnan(self.z_spread) else self.z_spread**2))

    @property
    def n_terms(self) -> int:
        return 1 + (0 if np.isnan(self.z_spread) else 1)

    def significant(self, alpha: float) -> bool:
        return bool(self.p_holm < alpha or self.p_spread_holm < alpha)

    def kinds(self, alpha: float) -> str:
        """Which of mean / spread is significant ("mean", "spread", "mean+spread" or "")."""
        return "+".join(k for k, p in (("mean", self.p_holm), ("spread", self.p_spread_holm)) if p < alpha)


@dataclass(frozen=True)
class Comparison:
    """Every condition's gap, the family-wise `alpha`, and the gap measure D = sum of squared normal scores."""

    gaps: tuple[ConditionGap, ...]
    alpha: float
    D: float

    @property
    def significant(self) -> list[ConditionGap]:
        return [g for g in self.gaps if g.significant(self.alpha)]

    @property
    def n_terms(self) -> int:
        """Terms of D (a mean term per condition, a spread term where the measured SD is known)."""
        return sum(g.n_terms for g in self.gaps)

    def gof_p(self, k: int = 0) -> float:
        """Goodness of fit: P(chi-square(n_terms - k) >= D) (1 when no degrees of freedom are left)."""
        dof = self.n_terms - k
        return float(sps.chi2.sf(self.D, dof)) if dof > 0 else 1.0

    def gap(self, condition: str) -> ConditionGap:
        return next(g for g in self.gaps if g.condition == condition)

    def to_dict(self) -> dict:
        return {"D": self.D, "n_terms": self.n_terms, "gof_p": self.gof_p(), "alpha": self.alpha,
                "significant": [g.condition for g in self.significant],
                "conditions": [{**asdict(g), "difference": g.difference, "ci95": g.ci95,
                                "significant": g.kinds(self.alpha)} for g in self.gaps]}


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values: p_(i) * (m - i + 1), made monotone, capped at 1 (NaN kept)."""
    p = np.asarray(p, float)
    out = np.full_like(p, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    order = ok[np.argsort(p[ok])]
    scaled = p[order] * (len(ok) - np.arange(len(ok)))
    out[order] = np.minimum(np.maximum.accumulate(scaled), 1.0)
    return out


def normal_score(t: float, df: float) -> float:
    """Phi^-1(F_t(t; df)) with the sign of t; t itself where the tail underflows."""
    return float(normal_scores(t, df))


def normal_scores(t: np.ndarray, df: np.ndarray) -> np.ndarray:
    """`normal_score` of arrays (broadcast)."""
    t, df = np.broadcast_arrays(np.asarray(t, float), np.asarray(df, float))
    tail = sps.t.sf(np.abs(t), df)
    with np.errstate(invalid="ignore"):
        z = np.where(tail > 1e-300, sps.norm.isf(np.clip(tail, 1e-300, None)), np.abs(t))
    return np.copysign(np.minimum(z, np.abs(t)), t)


def excess_kurtosis(*samples: np.ndarray) -> float:
    """Pooled excess kurtosis of the mean-centred samples, floored at 0."""
    x = np.concatenate([s - s.mean() for s in samples])
    m2 = np.mean(x**2)
    return max(0.0, float(np.mean(x**4) / m2**2 - 3.0)) if m2 > 0 else 0.0


def log_sd_se(n1: float | np.ndarray, n2: float | np.ndarray, g2: float | np.ndarray) -> float | np.ndarray:
    """Standard error of ln(s1 / s2) (Bonett 2006), excess kurtosis g2 (scalars or arrays)."""
    return np.sqrt((2.0 / (n1 - 1) + g2 / n1) / 4.0 + (2.0 / (n2 - 1) + g2 / n2) / 4.0)


def compare(simulated: Mapping[str, np.ndarray], measured: Measured, reference: Callable[[str], str | None],
            alpha: float = 0.05, tests: bool = True) -> Comparison:
    """Test every measured condition against the simulated per-eye values (module docstring)."""
    gaps = [_gap(name, simulated, measured, reference, tests) for name in measured.conditions]
    adjusted = holm(np.array([g.p for g in gaps] + [g.p_spread for g in gaps]))
    n = len(gaps)
    gaps = [replace(g, p_holm=float(adjusted[i]), p_spread_holm=float(adjusted[n + i])) for i, g in enumerate(gaps)]
    return Comparison(tuple(gaps), alpha, float(sum(g.term for g in gaps)))


def gap_measure(simulated: Mapping[str, np.ndarray], measured: Measured,
                reference: Callable[[str], str | None], rows: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """D of many simulations at once: `simulated` maps each condition to (P, E) per-eye values of P
    simulations; returns (P,) equal to `compare(..., tests=False).D` of each row (NaN where a row has fewer
    than 2 finite eyes). The search scores its dense surrogate grids with it. `rows` as in `gap_terms`."""
    D = None
    for name in measured.conditions:
        z_mean, z_spread = _condition_terms(name, simulated, measured, reference, (rows or {}).get(name))
        term = z_mean**2 + np.where(np.isnan(z_spread), 0.0, z_spread**2)
        D = term if D is None else D + term
    return np.asarray(D, float)


def gap_terms(simulated: Mapping[str, np.ndarray], measured: Measured,
              reference: Callable[[str], str | None], rows: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """The signed normal scores whose squares sum to D (`gap_measure`), (P, 2 C): the mean and the spread term of
    each of the C measured conditions, in order (0 where a condition has no spread term). `rows` maps a condition
    with per-subject values to (P, S) indices into them: the measured subjects of each row (`term_covariance`)."""
    out = []
    for name in measured.conditions:
        z_mean, z_spread = _condition_terms(name, simulated, measured, reference, (rows or {}).get(name))
        out += [z_mean, np.where(np.isnan(z_spread), 0.0, z_spread)]
    return np.column_stack(out)


def term_covariance(simulated: Mapping[str, np.ndarray], measured: Measured, reference: Callable[[str], str | None],
                    *, B: int = BOOTSTRAP, seed: int = 0) -> np.ndarray:
    """Covariance (2 C, 2 C) of the terms of `gap_terms` of one simulation (`simulated`: (E,) per condition) over
    `B` bootstrap resamples of whole units (`_resamples`). Under "no gap" a term's variance is about 1 and two
    conditions of the same subjects correlate: what the chi-square reading of D and its Delta D = 1 uncertainties
    assume away (`search.sandwich_factor`)."""
    one = {k: np.asarray(v, float).ravel() for k, v in simulated.items()}
    eyes, means, rows = _resamples(len(next(iter(one.values()))), measured, B, seed)
    terms = gap_terms({k: v[eyes] for k, v in one.items()}, _with_means(measured, means), reference, rows)
    return np.cov(terms, rowvar=False)


def resampled_gap_measure(simulated: Mapping[str, np.ndarray], measured: Measured,
                          reference: Callable[[str], str | None], *, B: int = BOOTSTRAP, seed: int = 0) -> np.ndarray:
    """D (B, P) of P simulations (`simulated`: (P, E) per condition) under each of `B` bootstrap resamples of whole
    units (`_resamples`, the same for every simulation): where the minimum of D over the P points lands, resample by
    resample, is the estimate's bootstrap distribution (`search.EffectSearch.correct`)."""
    sims = {k: np.asarray(v, float) for k, v in simulated.items()}
    P, E = next(iter(sims.values())).shape
    eyes, means, rows = _resamples(E, measured, B, seed)
    out = np.empty((B, P))
    chunk = max(1, 200_000 // (P * E))  # resamples at a time: arrays of at most about 200,000 per condition
    for b in range(0, B, chunk):
        e = eyes[b:b + chunk]  # (b, E)
        part = {k: v[:, e].transpose(1, 0, 2).reshape(-1, E) for k, v in sims.items()}  # (b * P, E)
        sub = _with_means(measured, {name: np.repeat(m[b:b + chunk], P) for name, m in means.items()})
        picked = {name: np.repeat(r[b:b + chunk], P, axis=0) for name, r in rows.items()}
        out[b:b + len(e)] = gap_measure(part, sub, reference, picked).reshape(len(e), P)
    return out


def _resamples(E: int, measured: Measured, B: int, seed: int
               ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """`B` bootstrap resamples of whole units: the simulated eyes (B, E), drawn jointly across conditions; the
    measured subjects, rows (B, S) into each per-subject condition (one draw for every condition when the data are
    paired, so the terms' correlation through shared subjects is kept; each list on its own when they are
    independent samples); B means (B,) of each summary condition with an SD, redrawn from N(mean, sd^2 / n) (one
    without an SD stays fixed)."""
    rng = np.random.default_rng(seed)
    eyes = rng.integers(0, E, size=(B, E))
    listed = {name: c.values.size for name, c in measured.conditions.items() if c.values is not None}
    if measured.paired and listed:  # one draw of subjects for every condition
        joint = rng.integers(0, len(measured.subjects), size=(B, len(measured.subjects)))
        rows = dict.fromkeys(listed, joint)
    else:  # independent samples
        rows = {name: rng.integers(0, size, size=(B, size)) for name, size in listed.items()}
    means = {name: c.mean + float(c.sd) / np.sqrt(c.n) * rng.standard_normal(B)
             for name, c in measured.conditions.items() if c.values is None and c.sd is not None}
    return eyes, means, rows


def _with_means(measured: Measured, means: Mapping[str, np.ndarray]) -> Measured:
    """`measured` with the summary conditions of `means` given those (redrawn) means, an array each."""
    redrawn = {name: replace(measured.conditions[name], mean=m) for name, m in means.items()}
    return replace(measured, conditions={**measured.conditions, **redrawn})


def _compared(name: str, simulated: Mapping[str, np.ndarray], measured: Measured,
              reference: Callable[[str], str | None]) -> tuple[MeasuredCondition, str | None, bool, np.ndarray]:
    """One condition's measured data, its reference, whether it is compared as a paired contrast, and the simulated
    values compared (the contrast with the reference where paired; module docstring)."""
    if name not in simulated:
        raise ValueError(f"the simulation has no condition {name!r}; it has {', '.join(simulated)}")
    cond = measured.conditions[name]
    ref = reference(name)
    paired = measured.paired and cond.values is not None and ref in measured.conditions and \
        measured.conditions[ref].values is not None
    return cond, ref, paired, np.asarray(simulated[name], float) - (np.asarray(simulated[ref], float) if paired
                                                                    else 0.0)


def _condition_terms(name: str, simulated: Mapping[str, np.ndarray], measured: Measured,
                     reference: Callable[[str], str | None],
                     rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The mean and spread normal scores (P,) of one condition (module docstring; the spread NaN where it has no
    term); `rows` (P, S): the measured subjects of each row; a summary's `mean` may be an array (P,)."""
    cond, ref, paired, sim = _compared(name, simulated, measured, reference)
    sim = np.atleast_2d(sim)
    finite = np.isfinite(sim)
    n = finite.sum(axis=1)
    x = np.where(finite, sim, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = x.sum(axis=1) / n
        dev = np.where(finite, sim - mean[:, None], 0.0)
        s_sd = np.maximum(np.sqrt((dev**2).sum(axis=1) / (n - 1)), SD_FLOOR)
        s_sd = np.where(n >= 2, s_sd, np.nan)
        if cond.values is None and cond.sd is None:
            df = n - 1.0
            return normal_scores((mean - cond.mean) / (s_sd / np.sqrt(n)), df), np.full(len(sim), np.nan)
        meas = cond.values - measured.conditions[ref].values if paired else cond.values
        if meas is not None:
            meas = meas[rows] if rows is not None else meas  # (P, S) or (S,)
            m_mean, m_n = meas.mean(axis=-1), meas.shape[-1]
            m_sd = np.maximum(meas.std(axis=-1, ddof=1), SD_FLOOR)
        else:
            m_mean, m_sd, m_n = cond.mean, max(float(cond.sd), SD_FLOOR), cond.n
        v1, v2 = s_sd**2 / n, m_sd**2 / m_n
        t = (mean - m_mean) / np.sqrt(v1 + v2)
        df = (v1 + v2) ** 2 / (v1**2 / (n - 1) + v2**2 / (m_n - 1))
        m2, m4 = (dev**2).sum(axis=1), (dev**4).sum(axis=1)
        count = n.astype(float)
        if meas is not None:
            centred = meas - meas.mean(axis=-1, keepdims=True)
            m2, m4, count = m2 + np.sum(centred**2, axis=-1), m4 + np.sum(centred**4, axis=-1), count + m_n
        m2, m4 = m2 / count, m4 / count
        g2 = np.where(m2 > 0, np.maximum(0.0, m4 / np.where(m2 > 0, m2, 1.0) ** 2 - 3.0), 0.0)
        z_spread = np.log(s_sd / m_sd) / log_sd_se(n, m_n, g2)
        return normal_scores(t, df), z_spread


def _gap(name: str, simulated: Mapping[str, np.ndarray], measured: Measured, reference, tests: bool) -> ConditionGap:
    cond, ref, paired, sim = _compared(name, simulated, measured, reference)
    sim = sim[np.isfinite(sim)]
    if sim.size < 2:
        raise ValueError(f"condition {name!r}: fewer than 2 simulated eyes with a finite value")
    meas = cond.values - measured.conditions[ref].values if paired else cond.values
    compared = f"{name} - {ref} (paired)" if paired else name
    raw_sd = float(sim.std(ddof=1))
    s_sd = max(raw_sd, SD_FLOOR)
    if meas is None and cond.sd is None:
        t = (sim.mean() - cond.mean) / (s_sd / np.sqrt(sim.size))
        df = float(sim.size - 1)
        p = 2.0 * sps.t.sf(abs(t), df)
        return ConditionGap(name, compared, "one-sample t", float(sim.mean()), s_sd, sim.size, cond.mean, None,
                            cond.n, float(t), df, float(p), normal_score(float(t), df))
    m_mean = float(meas.mean()) if meas is not None else cond.mean
    m_raw_sd = float(meas.std(ddof=1)) if meas is not None else float(cond.sd)
    m_sd = max(m_raw_sd, SD_FLOOR)
    m_n = meas.size if meas is not None else cond.n
    w = welch_t_test_from_stats(float(sim.mean()), s_sd, sim.size, m_mean, m_sd, m_n)
    g2 = excess_kurtosis(sim, meas) if meas is not None else excess_kurtosis(sim)
    z_spread = float(np.log(s_sd / m_sd) / log_sd_se(sim.size, m_n, g2))
    p_spread = float(2.0 * sps.norm.sf(abs(z_spread)))
    test, p = "welch", float(w.p)
    if meas is not None and min(raw_sd, m_raw_sd) < SD_FLOOR:  # below the resolution (module docstring)
        test = "welch (resolution)"
    elif tests and meas is not None:
        p, p_spread = permutation_p(sim, meas, seed=zlib.crc32(name.encode()))
        test = "permutation"
    return ConditionGap(name, compared, test, float(sim.mean()), s_sd, sim.size, m_mean, m_sd, m_n, float(w.t),
                        float(w.df), p, normal_score(float(w.t), float(w.df)), z_spread, p_spread)


def _welch_t(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Welch t of rows of a (B, n1) against rows of b (B, n2)."""
    va, vb = a.var(axis=1, ddof=1) / a.shape[1], b.var(axis=1, ddof=1) / b.shape[1]
    return (a.mean(axis=1) - b.mean(axis=1)) / np.sqrt(np.maximum(va + vb, 1e-300))


def _log_sd_ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 0.5 * np.log(np.maximum(a.var(axis=1, ddof=1), 1e-300) / np.maximum(b.var(axis=1, ddof=1), 1e-300))


def permutation_p(sim: np.ndarray, meas: np.ndarray, *, seed: int, B: int = PERMUTATIONS) -> tuple[float, float]:
    """Two-sided Monte Carlo permutation p-values of the Welch t (means) and of ln(s_sim / s_meas) on the
    mean-centred values (spreads), B random relabellings of the pooled sample."""
    rng = np.random.default_rng(seed)
    n1 = sim.size
    order = np.argsort(rng.random((B, n1 + meas.size)), axis=1)

    def p_of(x: np.ndarray, y: np.ndarray, stat) -> float:
        observed = float(stat(x[None], y[None])[0])
        pooled = np.concatenate([x, y])[order]
        null = stat(pooled[:, :n1], pooled[:, n1:])
        return float((1 + np.sum(np.abs(null) >= abs(observed) - 1e-12)) / (B + 1))

    return p_of(sim, meas, _welch_t), p_of(sim - sim.mean(), meas - meas.mean(), _log_sd_ratio)


def permutation_gof(simulated: Mapping[str, np.ndarray], measured: Measured, reference: Callable[[str], str | None],
                    D: float, *, B: int = GOF_PERMUTATIONS, seed: int = 0) -> float | None:
    """P(D* >= D) under relabelling of whole units between simulated eyes and measured subjects (module
    docstring); None unless every measured condition has per-subject values."""
    if any(c.values is None for c in measured.conditions.values()):
        return None
    keys = list(dict.fromkeys([*measured.conditions, *(r for c in measured.conditions if (r := reference(c))
                                                        and r in measured.conditions)]))
    sim = np.column_stack([np.asarray(simulated[k], float) for k in keys])
    sim = sim[np.all(np.isfinite(sim), axis=1)]
    meas = np.column_stack([measured.conditions[k].values for k in keys])
    pooled, n = np.vstack([sim, meas]), len(sim)
    if n < 2 or len(meas) < 2:
        return None
    rng = np.random.default_rng(seed)
    exceed = 0
    for _ in range(B):
        order = rng.permutation(len(pooled))
        s_part, m_part = pooled[order[:n]], pooled[order[n:]]
        fake = Measured(measured.experiment, {k: MeasuredCondition.of(m_part[:, i]) for i, k in enumerate(keys)
                                              if k in measured.conditions}, measured.subjects)
        d = compare({k: s_part[:, i] for i, k in enumerate(keys)}, fake, reference, tests=False).D
        exceed += d >= D - 1e-12
    return float((1 + exceed) / (B + 1))
