"""Write a replication run to a folder: summary.json, per_eye.csv, report.md and the figures (PNG)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.analysis.study import figures
from eyehil.analysis.study.findings import all_findings
from eyehil.analysis.study.published import CONFIGURATIONS, blignaut_real, fischer_simulated, guestrin_real_deg
from eyehil.analysis.study.replication import StudyResult
from eyehil.analysis.study.summary import best_function_errors, error_columns
from eyehil.emulator.eye.population import study_parameters
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene


def write_outputs(result: StudyResult, summary: dict[str, Any], out: Path) -> list[Path]:
    """Everything a run produces, in `out` (created)."""
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "summary.json", out / "per_eye.csv"]
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=_json) + "\n", encoding="utf-8")
    _per_eye_csv(result, out / "per_eye.csv")
    written += _figures(result, summary, out)
    (out / "report.md").write_text(render_markdown(summary, [p.name for p in written if p.suffix == ".png"]),
                                   encoding="utf-8")
    return [*written, out / "report.md"]


def _json(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value)}")


def _per_eye_csv(result: StudyResult, path: Path) -> None:
    params = study_parameters(result.eyes)
    columns = {**params, **{f"{k}_deg": v for k, v in error_columns(result).items()}}
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["eye", *columns])
        for i in range(len(result.eyes)):
            writer.writerow([i + 1, *(f"{columns[k][i]:.6g}" for k in columns)])


def _figures(result: StudyResult, summary: dict[str, Any], out: Path) -> list[Path]:
    params = study_parameters(result.eyes)
    names = list(params)
    X = np.column_stack([params[k] for k in names])
    cols = error_columns(result)
    best = summary["blignaut"]["best_function"]
    return [
        figures.table4(params, fischer_simulated()["table4_parameter_distribution"], out / "table4.png"),
        _features_figure(result, out / "fig3_features.png"),
        figures.guestrin({"H1": result.h1, "H2": result.h2}, guestrin_real_deg(), fischer_simulated(),
                         out / "fig4_guestrin.png"),
        figures.sensitivity(X, names, {k: cols[k] for k in ("H1", "H2")}, summary["sensitivity"],
                            out / "fig5_sensitivity_guestrin.png", "Guestrin: partial regression"),
        figures.blignaut(best_function_errors(result.blignaut_errors), blignaut_real()["best_error"],
                         {c: best[c]["model"] for c in CONFIGURATIONS}, out / "fig6_blignaut.png"),
        figures.sensitivity(X, names, {k: cols[k] for k in CONFIGURATIONS}, summary["sensitivity"],
                            out / "fig7_sensitivity_blignaut.png", "Blignaut: partial regression"),
    ]


def _features_figure(result: StudyResult, path: Path) -> Path:
    """Fig. 3 for the two eyes of most and least negative Q_ac (right eye, Blignaut scene)."""
    q = result.eyes.anterior_conic
    pick = [int(np.argmin(q)), int(np.argmax(q))]
    f = simulate(result.eyes[pick], load_scene("blignaut2014"))
    labels = [f"eye {i + 1} (Q_ac {q[i]:+.2f})" for i in pick]
    return figures.features(f.pupil_centre_px[:, 0, 0], f.glint_px[:, 0, 0, :, 0, :], labels, path)


def _row(*cells: Any) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def render_markdown(s: dict[str, Any], pngs: list[str]) -> str:
    """The report: findings, then each table beside its published values, then the figures."""
    pub = fischer_simulated()
    lines = ["# Replication of Fischer, van der Merwe & Vandenheever 2023", "",
             f"Settings: {json.dumps(s['settings'], default=_json)}", "", "## Findings", "",
             _row("published finding", "replicated", "holds"), _row("---", "---", "---")]
    notes: list[str] = []
    for f in all_findings(s):
        mark = ""
        if not f.holds and f.note:
            if f.note not in notes:
                notes.append(f.note)
            mark = f" [{notes.index(f.note) + 1}]"
        lines.append(_row(f.claim, f.replicated, ("yes" if f.holds else "**no**") + mark))
    lines += [""] + [f"[{i + 1}] {n}" for i, n in enumerate(notes)]
    lines += ["", "## Table 4: eye parameters (mean +- SD)", "", _row("parameter", "replicated", "published"),
              _row("---", "---", "---")]
    for k, (m, sd) in s["table4"].items():
        p = pub["table4_parameter_distribution"].get(k)
        lines.append(_row(k, f"{m:.3f} +- {sd:.3f}", f"{p[0]} +- {p[1]}" if p else "-"))
    g = s["guestrin"]
    lines += ["", f"## Guestrin & Eizenman 2006 (estimator corneal index n1 = {g['n1']})", "",
              _row("", "mean", "SD", "skewness", "Welch t (df) p vs real", "F (df) p vs real", "published", "real"),
              _row(*["---"] * 8)]
    for k in ("H1", "H2"):
        w, f = g["welch_t"][k], g["f_test"][k]
        lines.append(_row(k, f"{g[k]['mean']:.3f}", f"{g[k]['sd']:.3f}", f"{g[k]['skewness']:.2f}",
                          f"{w['statistic']:.2f} ({w['df']:.2f}) {w['p']:.3f}",
                          f"{f['statistic']:.2f} ({f['df'][0]:.0f}, {f['df'][1]:.0f}) {f['p']:.3f}",
                          f"{pub[k]['mean']} +- {pub[k]['sd']}",
                          f"{g['real'][k]['mean']:.3f} +- {g['real'][k]['sd']:.3f}"))
    lines += _blignaut_tables(s)
    lines += _sensitivity_table(s)
    lines += ["", "## Figures", ""] + [f"![{p}]({p})" for p in pngs]
    return "\n".join(lines) + "\n"


def _blignaut_tables(s: dict[str, Any]) -> list[str]:
    b, real = s["blignaut"], blignaut_real()
    lines = ["", "## Blignaut 2014: mean error (deg) by model and configuration, replicated / real", "",
             _row("model", *CONFIGURATIONS), _row(*["---"] * 7)]
    for m, row in b["by_model"].items():
        cells = [("n/a" if row[c] is None else f"{row[c]:.3f}") + f" / {real['by_model'][int(m) - 1][i]}"
                 for i, c in enumerate(CONFIGURATIONS)]
        lines.append(_row(m, *cells))
    lines += ["", "n/a: fewer calibration targets than terms (the real table lists such fits; their solver is not "
              "stated). The one-sample t-tests compare the replicated eyes with the real best-function mean (the "
              "published test ran the other way, t(25) over the 26 real participants, whose individual errors are "
              "not published).", "", _row("configuration", "best model (replicated / real)", "mean (replicated / real)",
                                   "one-sample t (df) p"), _row(*["---"] * 4)]
    for c in CONFIGURATIONS:
        rb, t = b["real_best_function"][c], b["one_sample_t"][c]
        lines.append(_row(c, f"{b['best_function'][c]['model']} / {rb['model']}",
                          f"{b['best_function'][c]['mean']:.3f} / {rb['mean']}",
                          f"{t['statistic']:.1f} ({t['df']:.0f}) {t['p']:.2g}"))
    return lines


def _sensitivity_table(s: dict[str, Any]) -> list[str]:
    lines = ["", "## Sensitivity (deg per SD; significant parameters, strongest first)", "",
             _row("error", "significant: coefficient (p)", "R^2 (significant)", "R^2 (all 11)"), _row(*["---"] * 4)]
    for col, r in s["sensitivity"].items():
        sig = ", ".join(f"{n} {r['coefficients'][n]['coef']:+.3f} ({r['coefficients'][n]['p']:.2g})"
                        for n in r["significant"]) or "none"
        lines.append(_row(col, sig, f"{r['r_squared']:.3f}", f"{r['r_squared_all']:.3f}"))
    return lines
