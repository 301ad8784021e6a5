"""The published findings the replication is checked against, each with the replicated numbers and a verdict.

Ranges are those the replication issue set out from the published study (Fischer et al. 2023); a
departure is reported with its numbers and, where investigated, the likely reason. Nothing here feeds
back into the simulation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Finding:
    """One published finding: what was claimed, what we got, whether it holds, and why not if known."""

    claim: str
    replicated: str
    holds: bool
    note: str = ""


GUESTRIN_LEVEL_NOTE = (
    "The replicated Guestrin errors are lower than the published 0.36 deg while their structure (skew, only Q_ac "
    "significant, H2 = H1) replicates. Investigated and excluded as the cause (each moves the mean by < 0.02 deg): "
    "the estimator's corneal index (1.3375 vs the study code's 1.376, absorbed by K), the media (Cauchy at 850 nm vs "
    "the study code's fixed indices), the calibration objective (least squares vs a Nelder-Mead search on the mean "
    "error: 0.23 vs 0.21 deg on 20 eyes). Not reproducible from the text: the study's exact fixation of the "
    "line of sight (gkaModelEye's nodal-point visual axis) and its solver's stopping point. The published Welch t "
    "values also imply simulated means of about 0.37-0.38, not the printed 0.36."
)


def _fmt(x: float) -> str:
    return f"{x:.3f}"


def guestrin_findings(s: dict[str, Any]) -> list[Finding]:
    g, sens = s["guestrin"], s["sensitivity"]
    out = []
    for key in ("H1", "H2"):
        m, sd, sk = g[key]["mean"], g[key]["sd"], g[key]["skewness"]
        out.append(Finding(f"Guestrin {key}: mean 0.30-0.42 deg (published 0.36)", _fmt(m), 0.30 <= m <= 0.42,
                           GUESTRIN_LEVEL_NOTE))
        out.append(Finding(f"Guestrin {key}: SD 0.12-0.28 deg (published 0.20)", _fmt(sd), 0.12 <= sd <= 0.28))
        out.append(Finding(f"Guestrin {key}: right-skewed (published {1.86 if key == 'H1' else 1.84})", f"{sk:.2f}",
                           sk > 0))
        r = sens[key]
        only_q = r["significant"] == ["Q_ant_cornea"]
        coef = abs(r["coefficients"]["Q_ant_cornea"]["coef"])
        out.append(Finding(f"{key}: Q_ac the only significant parameter", ", ".join(r["significant"]) or "none",
                           only_q, "secondary parameters reach p < .05 with effects an order of magnitude "
                           "smaller than Q_ac's (see the sensitivity table)"))
        others = [abs(r["coefficients"][n]["coef"]) for n in r["significant"] if n != "Q_ant_cornea"]
        dominant = bool(r["significant"]) and r["significant"][0] == "Q_ant_cornea" and all(
            5 * o <= abs(r["coefficients"]["Q_ant_cornea"]["coef"]) for o in others)
        out.append(Finding(f"{key}: Q_ac the dominant parameter (>= 5x any other significant one; our check)",
                           ", ".join(f"{n} {r['coefficients'][n]['coef']:+.3f}" for n in r["significant"]), dominant))
        out.append(Finding(f"{key}: |Q_ac coefficient| 0.15-0.25 deg/SD (published 0.2)", _fmt(coef),
                           0.15 <= coef <= 0.25, "follows the lower error level (see the mean)"))
        out.append(Finding(f"{key}: R^2 >= 0.9 (published .99)", f"{r['r_squared']:.3f}", r["r_squared"] >= 0.9))
    return out


def blignaut_findings(s: dict[str, Any]) -> list[Finding]:
    best = s["blignaut"]["best_function"]
    drop = best["C5"]["mean"] - best["C9"]["mean"]
    later = [abs(best[b]["mean"] - best[a]["mean"]) for a, b in (("C14", "C18"), ("C18", "C23"), ("C23", "C135"))]
    out = [
        Finding("Blignaut: best-function error falls 0.1-0.3 deg from C5 to C9 (published 0.20, real 0.28)",
                _fmt(drop), 0.1 <= drop <= 0.3),
        Finding("Blignaut: changes below 0.1 deg beyond C14", _fmt(max(later)), max(later) < 0.1),
    ]
    strongest = [s["sensitivity"][c]["significant"][:1] for c in ("C5", "C9", "C14", "C18", "C23", "C135")]
    q_first = all(x == ["Q_ant_cornea"] for x in strongest)
    out.append(Finding("Blignaut: Q_ac the strongest parameter at every configuration",
                       ", ".join(x[0] if x else "none" for x in strongest), q_first))
    t = s["blignaut"]["one_sample_t"]
    different = all(v["p"] < 0.05 for v in t.values())
    out.append(Finding("Blignaut: simulated level significantly different from the real one (published t(25) > 5.34)",
                       f"min |t| {min(abs(v['statistic']) for v in t.values()):.1f}", different))
    return out


def all_findings(summary: dict[str, Any]) -> list[Finding]:
    return guestrin_findings(summary) + blignaut_findings(summary)
