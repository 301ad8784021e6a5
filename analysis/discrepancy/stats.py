"""Where a simulation and measured data disagree: one test per condition and a chi-square-like gap measure.

Per condition c (degrees), the compared quantity is the condition itself, or, for paired measured data
and a condition with a reference r (H2 and head:* refer to H1), the within-subject difference c - r,
computed the same way for every simulated eye and every measured subject. Then:

- per-subject measured values, or a summary with an SD: Welch's t-test of the simulated mean against the
  measured mean (`eyehil.analysis.study.stats.welch_t_test_from_stats`; Welch-Satterthwaite df);
- a summary without an SD (Blignaut 2014's published means): the one-sample t-test of the simulated eyes
  against the measured mean, t = (mean - mu) / (s / sqrt(n)), df = n - 1, as the published study did.

SDs below `SD_FLOOR_DEG` are raised to it (a noiseless contrast can be exactly 0.0). p-values are two-sided;
`p_holm` is Holm's step-down adjustment over the compared conditions (family-wise error `alpha`), and a
gap is significant when p_holm < alpha.

The gap measure is D = sum_c t_c^2. Were the conditions independent and the t's normal, D would follow a
chi-square with one degree of freedom per condition under "no gap", and the drop of D when an effect with k
fitted parameters is added would follow chi-square(k) if the effect were absent: a likelihood-ratio-like
criterion. Conditions sharing subjects are correlated and small samples make t heavier-tailed than
normal, so D is a ranking measure with a calibrated-looking scale, not an exact test.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy import stats as sps

from eyehil.analysis.discrepancy.data import Measured
from eyehil.analysis.study.stats import welch_t_test_from_stats

SD_FLOOR_DEG = 1e-4


@dataclass(frozen=True)
class ConditionGap:
    """One condition: what was compared, both means (deg), the test and its Holm-adjusted p."""

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
    p_holm: float = float("nan")

    @property
    def difference(self) -> float:
        """Simulated minus measured mean (deg)."""
        return self.simulated - self.measured

    @property
    def ci95(self) -> float:
        """Half-width of the 95 % confidence interval of the difference (deg)."""
        se = abs(self.difference / self.t) if self.t else 0.0
        return float(sps.t.ppf(0.975, max(self.df, 1.0)) * se)


@dataclass(frozen=True)
class Comparison:
    """Every condition's gap, the family-wise `alpha`, and the gap measure D = sum t^2."""

    gaps: tuple[ConditionGap, ...]
    alpha: float
    D: float

    @property
    def significant(self) -> list[ConditionGap]:
        return [g for g in self.gaps if g.p_holm < self.alpha]

    def gap(self, condition: str) -> ConditionGap:
        return next(g for g in self.gaps if g.condition == condition)

    def to_dict(self) -> dict:
        return {"D": self.D, "alpha": self.alpha, "significant": [g.condition for g in self.significant],
                "conditions": [{**asdict(g), "difference": g.difference, "ci95": g.ci95} for g in self.gaps]}


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values: p_(i) * (m - i + 1), made monotone, capped at 1."""
    p = np.asarray(p, float)
    order = np.argsort(p)
    scaled = p[order] * (len(p) - np.arange(len(p)))
    adjusted = np.empty_like(p)
    adjusted[order] = np.minimum(np.maximum.accumulate(scaled), 1.0)
    return adjusted


def compare(simulated: Mapping[str, np.ndarray], measured: Measured, reference: Callable[[str], str | None],
            alpha: float = 0.05) -> Comparison:
    """Test every measured condition against the simulated per-eye values (module docstring)."""
    gaps = [_gap(name, simulated, measured, reference) for name in measured.conditions]
    adjusted = holm(np.array([g.p for g in gaps]))
    return Comparison(tuple(_with_p_holm(g, p) for g, p in zip(gaps, adjusted, strict=True)), alpha,
                      float(sum(g.t**2 for g in gaps)))


def _with_p_holm(g: ConditionGap, p: float) -> ConditionGap:
    return replace(g, p_holm=float(p))


def _gap(name: str, simulated: Mapping[str, np.ndarray], measured: Measured, reference) -> ConditionGap:
    if name not in simulated:
        raise ValueError(f"the simulation has no condition {name!r}; it has {', '.join(simulated)}")
    cond = measured.conditions[name]
    ref = reference(name)
    paired = measured.paired and cond.values is not None and ref in measured.conditions and \
        measured.conditions[ref].values is not None
    sim = np.asarray(simulated[name], float) - (np.asarray(simulated[ref], float) if paired else 0.0)
    sim = sim[np.isfinite(sim)]
    if sim.size < 2:
        raise ValueError(f"condition {name!r}: fewer than 2 simulated eyes with a finite value")
    meas = cond.values - measured.conditions[ref].values if paired else cond.values
    compared = f"{name} - {ref} (paired)" if paired else name
    s_sd = max(float(sim.std(ddof=1)), SD_FLOOR_DEG)
    if meas is not None or cond.sd is not None:
        m_mean = float(meas.mean()) if meas is not None else cond.mean
        m_sd = max(float(meas.std(ddof=1)) if meas is not None else float(cond.sd), SD_FLOOR_DEG)
        m_n = meas.size if meas is not None else cond.n
        w = welch_t_test_from_stats(float(sim.mean()), s_sd, sim.size, m_mean, m_sd, m_n)
        return ConditionGap(name, compared, "welch", float(sim.mean()), s_sd, sim.size, m_mean, m_sd, m_n,
                            w.t, w.df, w.p)
    t = (sim.mean() - cond.mean) / (s_sd / np.sqrt(sim.size))
    p = 2.0 * sps.t.sf(abs(t), sim.size - 1)
    return ConditionGap(name, compared, "one-sample", float(sim.mean()), s_sd, sim.size, cond.mean, None, cond.n,
                        float(t), float(sim.size - 1), float(p))
