"""Write a discrepancy run to a folder: summary.json (outcome, named effects in order, their parameters,
the gap before and after), result.json (everything), measured.json (the data, in its file format),
report.md and discrepancy.png (gap per condition before and after; D along each effect's parameter)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from eyehil.analysis.discrepancy.rounds import RIVAL_SCORE, Round
from eyehil.analysis.discrepancy.search import EffectFit
from eyehil.analysis.discrepancy.stats import Comparison
from eyehil.analysis.discrepancy.workflow import DiscrepancyResult
from eyehil.emulator import effects as registry


def write_outputs(result: DiscrepancyResult, out: Path) -> list[Path]:
    """Everything a run produces, in `out` (created)."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [result.measured.save(out / "measured.json"), out / "result.json", figure(result, out / "discrepancy.png")]
    (out / "result.json").write_text(json.dumps(to_dict(result), indent=1, default=_json) + "\n", encoding="utf-8")
    (out / "summary.json").write_text(json.dumps(result.summary(), indent=1, default=_json) + "\n", encoding="utf-8")
    (out / "report.md").write_text(render_markdown(result, "discrepancy.png"), encoding="utf-8")
    return [*paths, out / "summary.json", out / "report.md"]


def _json(value: Any) -> Any:
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    if isinstance(value, Comparison):
        return value.to_dict()
    raise TypeError(f"not JSON serialisable: {type(value)}")


def _fit_dict(f: EffectFit, level: float) -> dict[str, Any]:
    return {"effect": f.effect.name, "values": f.values, "sigma": f.sigma, "ci95": f.ci95, "D": f.D, "D0": f.D0,
            "explained": f.explained, "score": f.score, "lowers": f.lowers(level), "at_edge": f.at_edge,
            "passes": f.passes(level), "gof_p": f.gof_p, "screened_only": f.screened, "alternatives": f.alternatives,
            "evaluations": len(f.points)}


def to_dict(result: DiscrepancyResult) -> dict[str, Any]:
    rounds = [{"before": r.before.to_dict(), "verdict": r.verdict, "level": r.level,
               "ranking": [_fit_dict(f, r.level) for f in r.fits],
               "added": r.added.effect.name if r.added else None} for r in result.rounds]
    inter = result.interactions
    return {"settings": result.settings, "source": result.measured.source, "summary": result.summary(),
            "rounds": rounds, "added": [{"effect": a.effect.name, "values": dict(a.values)} for a in result.added],
            "final_search": result.final.to_dict(),
            "interactions": None if inter is None else {k: c.to_dict() for k, c in inter.comparisons.items()},
            "show": {"before": result.before.to_dict(), "after": result.after.to_dict(), "shrink": result.shrink}}


def _row(*cells: Any) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def _fitted(f: EffectFit) -> str:
    parts = []
    for p in f.effect.fitted:
        s = f.sigma.get(p.name, float("nan"))
        edge = " (at range edge)" if p.name in f.at_edge else ""
        parts.append(f"{p.name} = {f.values[p.name]:.4g}" + ("" if np.isnan(s) else f" +- {s:.2g}") + f" {p.unit}"
                     + edge)
    return ", ".join(parts) + (" (screened)" if f.screened else "")


def _gaps_table(c: Comparison) -> list[str]:
    lines = [_row("condition", "compared", "simulated", "measured", "difference (95% CI)", "t (df)", "test",
                  "Holm p mean", "SD sim / meas", "z spread", "Holm p spread", "gap"), _row(*["---"] * 12)]
    for g in c.gaps:
        sd = f"{g.simulated_sd:.3f} / {g.measured_sd:.3f}" if g.measured_sd is not None else f"{g.simulated_sd:.3f} / -"
        lines.append(_row(g.condition, g.compared, f"{g.simulated:.3f}", f"{g.measured:.3f}",
                          f"{g.difference:+.3f} (+- {g.ci95:.3f})", f"{g.t:+.2f} ({g.df:.1f})", g.test,
                          f"{g.p_holm:.3g}", sd, f"{g.z_spread:+.2f}", f"{g.p_spread_holm:.3g}",
                          f"**{g.kinds(c.alpha)}**" if g.significant(c.alpha) else "no"))
    return lines


def _round(i: int, r: Round) -> list[str]:
    lines = [f"### Round {i}", "", f"Find (D = {r.before.D:.2f} over {len(r.before.gaps)} conditions):", "",
             *_gaps_table(r.before), ""]
    if r.diffuse_p is not None:
        lines += [f"No condition is significant; D as a whole: goodness-of-fit p = {r.diffuse_p:.2g} "
                  f"({'a gap' if r.gap else 'no gap'} at alpha {r.before.alpha:g}).", ""]
    if r.fits:
        lines += [f"Name (every candidate effect screened, the best refined; ranked by D + 2k; passes: lowers D past "
                  f"the chi-square(k) point at {100 * r.level:.2f} %, Bonferroni over {len(r.fits)} candidates, "
                  "and no parameter at a range edge):", "",
                  _row("rank", "effect", "fitted (+- 1 sigma)", "D", "D0 - D", "explained", "D + 2k", "GOF p",
                       "passes", "also fits"), _row(*["---"] * 10)]
        for k, f in enumerate(r.fits, start=1):
            also = "; ".join(", ".join(f"{n} {v:.3g}" for n, v in a.items()) for a in f.alternatives) or "-"
            verdict = "yes" if f.passes(r.level) else ("edge" if f.lowers(r.level) and f.at_edge else "no")
            lines.append(_row(k, f.effect.name, _fitted(f), f"{f.D:.2f}", f"{f.reduction:.2f}",
                              f"{100 * f.explained:.0f} %", f"{f.score:.2f}", f"{f.gof_p:.2g}", verdict, also))
        lines.append("")
    lines.append(f"Verdict: {r.verdict}.")
    if r.backfitted:
        lines.append("Backfitted in the added effect's place, the whole model's D + 2k: "
                     + "; ".join(f"{n} {v:.2f}" for n, v in sorted(r.backfitted.items(), key=lambda kv: kv[1])) + ".")
    if r.rivals:
        lines.append(f"The data cannot tell {r.added.effect.name} from {', '.join(r.rivals)}: D + 2k within "
                     f"{RIVAL_SCORE:g} of its own.")
    if r.added is not None and r.added.effect.twins:
        lines.append(f"No recording tells {r.added.effect.name} from its twin {', '.join(r.added.effect.twins)}: "
                     "at matched values they change every condition alike (docs/discrepancy.md, the catalogue).")
    return [*lines, ""]


def _interactions(result: DiscrepancyResult) -> list[str]:
    """Which effect closes which part of each gap: the difference per condition with each alone and together."""
    inter = result.interactions
    names = list(inter.alone)
    lines = ["", "## The added effects alone and together (search eyes)", "",
             f"D without effects {inter.D0:.2f}; " + "; ".join(f"{n} alone {d:.2f}" for n, d in inter.alone.items())
             + f"; together {inter.together:.2f}; interaction (D0 - D_all - sum of the drops alone) "
             f"{inter.interaction:+.2f}.", "",
             _row("condition", "difference without", *[f"with {n} alone" for n in names], "with all"),
             _row(*["---"] * (len(names) + 3))]
    first = result.rounds[0].before
    for i, g in enumerate(first.gaps):
        cells = [f"{inter.comparisons[n].gaps[i].difference:+.3f}" for n in names]
        lines.append(_row(g.compared, f"{g.difference:+.3f}", *cells,
                          f"{inter.comparisons['together'].gaps[i].difference:+.3f}"))
    return lines


def render_markdown(result: DiscrepancyResult, png: str) -> str:
    """The report: data, rounds (find, name, add), the show comparison, the effects, the figure."""
    s, m = result.settings, result.measured
    named = ", ".join(a.label() for a in result.named) or "none"
    lines = [f"# Discrepancy workflow: {s['experiment']}", "", f"**Outcome: {result.outcome}** ({result.reason}). "
             f"Named effects, largest first: {named}.", "", f"Measured data: {m.source} "
             f"({len(m.conditions)} conditions{', paired by subject' if m.paired else ''}).", "",
             f"Settings: {s['search_eyes']} search eyes, {s['eyes']} show eyes, up to {s['rounds']} rounds, "
             f"family-wise alpha {s['alpha']}, noise seed {s['seed']}, {s['evaluations']} evaluations "
             "(each a simulation and a calibration of the search eyes).", "",
             "D = sum over conditions of the squared normal scores of the mean and the spread tests "
             "(analysis/discrepancy/stats.py). The top-ranked effect is added when it lowers D, divided by the "
             "misfit scale s^2 = max(1, D / (n - k)), by more than the point of chi-square(k) for its k fitted "
             "parameters at the round's level (Bonferroni over its candidates: 1 - 0.05 / m) and no parameter is at "
             "the edge of its plausible range. The outcome is 'explained' only if "
             f"no significant gap is left and P(chi-square) of the final D >= {s.get('alpha_gof', 0.01)} "
             "(docs/discrepancy.md).", "",
             "## Rounds", ""]
    for i, r in enumerate(result.rounds, start=1):
        lines += _round(i, r)
    added = ", ".join(a.label() for a in result.added) or "nothing"
    left = ", ".join(g.compared for g in result.after.significant) or "none"
    lines += ["## Show: the gap before and after", "", f"Added: {added}. On the {s['eyes']} show eyes D goes from "
              f"{result.before.D:.2f} to {result.after.D:.2f} (shrink {100 * result.shrink:.1f} %); significant "
              f"gaps left: {left}.", "",
              _row("condition", "measured", "simulated before", "Holm p before", "simulated after", "Holm p after"),
              _row(*["---"] * 6)]
    for b, a in zip(result.before.gaps, result.after.gaps, strict=True):
        lines.append(_row(b.compared, f"{b.measured:.3f}", f"{b.simulated:.3f}", f"{b.p_holm:.3g}",
                          f"{a.simulated:.3f}", f"{a.p_holm:.3g}"))
    if result.interactions is not None:
        lines += _interactions(result)
    if m.extra.get("hidden"):
        lines += ["", f"Truth (hidden from the workflow): {', '.join(m.extra['hidden'])}."]
    lines += ["", "## Effects in the catalogue", "",
              _row("effect", "parameters (unit, default, range)", "prior", "reference"), _row(*["---"] * 4)]
    for name in registry.names():
        e = registry.get(name)
        params = "; ".join(f"{p.name} ({p.unit or '-'}, {p.default:g}, [{p.low:g}, {p.high:g}]"
                           f"{'' if p.fitted else ', fixed'})" for p in e.parameters)
        lines.append(_row(f"{name}: {e.summary()}", params, e.prior, e.reference))
    return "\n".join([*lines, "", f"![{png}]({png})", ""])


def figure(result: DiscrepancyResult, path: Path) -> Path:
    """(a) simulated - measured per condition with 95 % CI, before and after; (b) D along each parameter."""
    fig = Figure(figsize=(13, 5))
    a, b = fig.subplots(1, 2)
    y = np.arange(len(result.before.gaps))
    for comp, label, dy, colour in ((result.before, "before", -0.15, "#999999"), (result.after, "after", 0.15,
                                                                                   "#4c72b0")):
        a.errorbar([g.difference for g in comp.gaps], y + dy, xerr=[g.ci95 for g in comp.gaps], fmt="o",
                   color=colour, capsize=3, label=f"{label} (D = {comp.D:.1f})")
    a.axvline(0, color="k", lw=0.8)
    a.set_yticks(y, [g.compared for g in result.before.gaps], fontsize=8)
    a.invert_yaxis()
    a.set_xlabel("simulated - measured (deg)")
    a.set_title("(a) gap per condition, show eyes (95 % CI)")
    a.legend(fontsize=8)
    _profiles(b, result)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _profiles(ax, result: DiscrepancyResult) -> None:
    fits = [f for r in result.rounds[:1] for f in r.fits][:6]  # the six best ranked
    for f in fits:
        p = f.effect.fitted[0]
        x = (f.points[:, 0] - p.low) / (p.high - p.low)
        xs = np.unique(x)
        ds = np.array([f.Ds[x == v].min() for v in xs])
        extra = " (min over the rest)" if f.k > 1 else ""
        ax.plot(xs, ds, ".-", label=f"{f.effect.name}: {p.name} [{p.low:g}, {p.high:g}]{extra}")
    if fits:
        ax.axhline(fits[0].D0, color="k", ls=":", lw=0.8, label="D without an effect")
        ax.set_yscale("log")
        ax.legend(fontsize=7, loc="best", framealpha=0.8)
    ax.set_xlabel("parameter, fraction of its plausible range")
    ax.set_ylabel("gap measure D (search eyes)")
    ax.set_title("(b) round 1: D along each effect's parameter")
