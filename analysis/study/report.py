"""Write a replication run to a folder: summary.json, per_eye.csv, report.md and the figures (PNG)."""

from __future__ import annotations

import csv
import json
import signal
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.analysis.study import figures
from eyehil.analysis.study.breakdown import COMPONENTS, GROUPS, NEGLIGIBLE_DEG
from eyehil.analysis.study.findings import all_findings
from eyehil.analysis.study.published import CONFIGURATIONS, blignaut_real, fischer_simulated, guestrin_real_deg
from eyehil.analysis.study.replication import StudyResult
from eyehil.analysis.study.summary import best_function_errors, error_columns
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.population import study_parameters
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene
from eyehil.parallel import default_workers, worker_pool


def write_outputs(result: StudyResult, summary: dict[str, Any], out: Path,
                  full: StudyResult | None = None, workers: int | None = None) -> list[Path]:
    """Everything a run produces, in `out` (created); `full`: the same eyes with full anatomy (`--anatomy full`,
    compared in `summary["anatomy"]` and fig. 9). The figures are drawn by `workers` processes (default one per
    core; 1: in this process)."""
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "summary.json", out / "per_eye.csv"]
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=_json) + "\n", encoding="utf-8")
    _per_eye_csv(result, out / "per_eye.csv")
    jobs = _figures(result, summary, out)
    if full is not None:
        jobs.append(partial(_anatomy_figure, result, full, summary, out / "fig9_anatomy.png"))
    if "anatomy_breakdown" in summary:
        jobs.append(partial(figures.breakdown, summary["anatomy_breakdown"], COMPONENTS, GROUPS,
                            out / "fig10_anatomy_breakdown.png"))
    written += _draw(jobs, workers)
    pngs = [p.name for p in written if p.suffix == ".png"]
    written += [figures.svg_of(p) for p in written if p.suffix == ".png"]
    (out / "report.md").write_text(render_markdown(summary, pngs), encoding="utf-8")
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


def _draw(jobs: list[partial], workers: int | None) -> list[Path]:
    """Run the figure jobs (each writes one figure and returns its PNG path), in order; in a pool of worker
    processes when more than one worker is available (each figure is independent: the wall time halves on two
    cores), else here. The pool is `eyehil.parallel.worker_pool`'s: Ctrl-C stops it at once (its docstring)."""
    workers = min(workers or default_workers(), len(jobs))
    if workers <= 1:
        return [job() for job in jobs]
    with worker_pool(workers) as pool:
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # no Ctrl-C while workers fork
        try:
            futures = [pool.submit(job) for job in jobs]
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        return [f.result() for f in futures]


def _figures(result: StudyResult, summary: dict[str, Any], out: Path) -> list[partial]:
    params = study_parameters(result.eyes)
    names = list(params)
    X = np.column_stack([params[k] for k in names])
    cols = error_columns(result)
    best = summary["blignaut"]["best_function"]
    # Table 4 measures ACD from the anterior cornea (CCT + ACD); the sensitivity columns from the posterior
    table = {("ACD_from_anterior_cornea_mm" if k == "ACD_mm" else k): (v + params["CCT_mm"] if k == "ACD_mm" else v)
             for k, v in params.items()} | {"n_lens": result.eyes.lens_index}
    return [
        partial(figures.table4, table, fischer_simulated()["table4_parameter_distribution"], out / "table4.png"),
        partial(_features_figure, result.eyes, out / "fig3_features.png"),
        partial(figures.guestrin, {"H1": result.h1, "H2": result.h2}, guestrin_real_deg(), fischer_simulated(),
                out / "fig4_guestrin.png"),
        partial(figures.sensitivity, X, names, {k: cols[k] for k in ("H1", "H2")}, summary["sensitivity"],
                out / "fig5_sensitivity_guestrin.png", "Guestrin: partial regression"),
        partial(figures.blignaut, best_function_errors(result.blignaut_errors), blignaut_real()["best_error"],
                {c: best[c]["model"] for c in CONFIGURATIONS}, out / "fig6_blignaut.png"),
        partial(figures.sensitivity, X, names, {k: cols[k] for k in CONFIGURATIONS}, summary["sensitivity"],
                out / "fig7_sensitivity_blignaut.png", "Blignaut: partial regression"),
        *_profiles_figure(result, summary, out),
    ]


def _profiles_figure(result: StudyResult, summary: dict[str, Any], out: Path) -> list[partial]:
    compare = summary.get("guestrin_compare")
    if not compare:
        return []
    main = summary["guestrin"]["profile"]
    h1 = {main: result.profiles[main]["h1"], compare["profile"]: result.profiles[compare["profile"]]["h1"]}
    sens = {main: summary["sensitivity"], compare["profile"]: compare["sensitivity"]}
    return [partial(figures.profiles, h1, result.eyes.anterior_conic, sens, out / "fig8_estimator_profiles.png")]


def _anatomy_figure(paper: StudyResult, full: StudyResult, summary: dict[str, Any], path: Path) -> Path:
    """Fig. 9: H1 of the main profile, paper vs full anatomy, on the full run's significant parameters."""
    column = f"H1 {summary['guestrin']['profile']}"
    params = study_parameters(full.eyes)
    names = list(params)
    X = np.column_stack([params[k] for k in names])
    return figures.anatomy(X, names, {"paper": paper.h1, "full": full.h1},
                           summary["anatomy"][column]["full"]["significant"], path, column)


def _features_figure(eyes: EyeModel, path: Path) -> Path:
    """Fig. 3 for the two eyes of most and least negative Q_ac (right eye, Blignaut scene)."""
    q = eyes.anterior_conic
    pick = [int(np.argmin(q)), int(np.argmax(q))]
    f = simulate(eyes[pick], load_scene("blignaut2014"))
    labels = [f"eye {i + 1} (Q_ac {figures.signed(float(q[i]))})" for i in pick]
    title = (f"Fig. 3: image features of the right eye over the {f.pupil_centre_px.shape[3]} Blignaut targets, "
             "for the eyes of most and least negative Q_ac")
    return figures.features(f.pupil_centre_px[:, 0, 0], f.glint_px[:, 0, 0, :, 0, :], labels, path, title)


def _row(*cells: Any) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def render_markdown(s: dict[str, Any], pngs: list[str]) -> str:
    """The report: findings, then each table beside its published values, then the figures."""
    pub = fischer_simulated()
    lines = ["# Replication of Fischer, van der Merwe & Vandenheever 2023", "", "## Settings", ""]
    lines += _settings_table(s)
    lines += ["", "## Findings", "", _row("published finding", "replicated", "holds"), _row("---", "---", "---")]
    notes: list[str] = []
    for f in all_findings(s):
        mark = ""
        if not f.holds and f.note:
            if f.note not in notes:
                notes.append(f.note)
            mark = f" [{notes.index(f.note) + 1}]"
        lines.append(_row(f.claim, f.replicated, ("yes" if f.holds else "**no**") + mark))
    lines += [""] + [f"[{i + 1}] {n}" for i, n in enumerate(notes)]
    lines += _departures(s)
    lines += ["", "## Table 4: eye parameters (mean +- SD)", "", _row("parameter", "replicated", "published"),
              _row("---", "---", "---")]
    for k, (m, sd) in s["table4"].items():
        p = pub["table4_parameter_distribution"].get(k)
        lines.append(_row(k, f"{m:.3f} +- {sd:.3f}", f"{p[0]} +- {p[1]}" if p else "-"))
    g = s["guestrin"]
    lines += ["", f"## Guestrin & Eizenman 2006 (estimator profile {g['profile']})", "",
              _row("", "mean", "SD", "skewness", "Welch t (df) p vs real", "F (df) p vs real", "published", "real"),
              _row(*["---"] * 8)]
    for k in ("H1", "H2"):
        w, f = g["welch_t"][k], g["f_test"][k]
        lines.append(_row(k, f"{g[k]['mean']:.3f}", f"{g[k]['sd']:.3f}", f"{g[k]['skewness']:.2f}",
                          f"{w['statistic']:.2f} ({w['df']:.2f}) {w['p']:.3f}",
                          f"{f['statistic']:.2f} ({f['df'][0]:.0f}, {f['df'][1]:.0f}) {f['p']:.3f}",
                          f"{pub[k]['mean']} +- {pub[k]['sd']}",
                          f"{g['real'][k]['mean']:.3f} +- {g['real'][k]['sd']:.3f}"))
    lines += _profiles_section(s)
    lines += _anatomy_section(s)
    lines += _breakdown_section(s)
    lines += _blignaut_tables(s)
    lines += _sensitivity_table(s)
    lines += _univariate_table(s)
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
    missing = {c: n for c, n in b.get("eyes_without_error", {}).items() if n}
    if missing:
        lines += ["", "Eyes without a best-function error (every fit failed or no valid sample), left out of the "
                  "means and tests: " + ", ".join(f"{c} {n}" for c, n in missing.items()) + "."]
    return lines


def _sensitivity_table(s: dict[str, Any]) -> list[str]:
    lines = ["", "## Sensitivity (deg per SD; significant parameters, strongest first)", "",
             _row("error", "significant: coefficient (p)", "R^2 (significant)", "R^2 (all 11)"), _row(*["---"] * 4)]
    for col, r in s["sensitivity"].items():
        sig = ", ".join(f"{n} {r['coefficients'][n]['coef']:+.3f} ({r['coefficients'][n]['p']:.2g})"
                        for n in r["significant"]) or "none"
        lines.append(_row(col, sig, f"{r['r_squared']:.3f}", f"{r['r_squared_all']:.3f}"))
    return lines


def _settings_table(s: dict[str, Any]) -> list[str]:
    st, counts = s["settings"], s.get("counts", {})
    rows = [("eyes", st.get("eyes", "-")), ("Guestrin estimator profile", st.get("guestrin_profile")),
            ("comparison profile (same features)", st.get("compare_profile") or "none")]
    for name, opts in st.get("estimator_options", {}).items():
        rows.append((f"options of {name}", ", ".join(f"{k} {v}" for k, v in opts.items())))
    heads = st.get("head_offsets_mm", {})
    rows.append(("Guestrin head positions", f"{st.get('head_positions')}: " + ", ".join(
        f"{n} ({', '.join(f'{v:g}' for v in off)} mm)" for n, off in heads.items())))
    rows.append(("why these head positions", "the study's code (tests/environment_gues.m) moved the head +-30 mm "
                 "vertically and +-40 mm horizontally, which produced the published numbers; the paper's text "
                 "(30 mm left/right, 40 mm forward/back) is the named alternative --head-positions paper-text"))
    rows += [("scenes", f"{st.get('guestrin_scene')}, {st.get('blignaut_scene')}"),
             ("ocular media", f"{st.get('media')} at {st.get('wavelength_nm')} nm"),
             ("estimators", "batched across eyes" if st.get("batched") else "per eye"),
             ("run time", f"{st.get('seconds', float('nan')):.1f} s")]
    off, total = counts.get("guestrin_off_sensor"), counts.get("guestrin_fixations")
    if off is not None and total:
        rows.append(("off-sensor fixations", f"Guestrin {off} of {total} ({100 * off / total:.0f}%), Blignaut "
                     f"{counts.get('blignaut_off_sensor', 0)} of {counts.get('blignaut_fixations', 0)}: features "
                     "outside the 640 x 480 sensor (the eye leaves the narrow 35 mm-lens field at the moved head "
                     "positions); the study's ray tracer did not clip them, so they are used, not excluded. "
                     f"Invalid (no solution) and excluded: Guestrin {total - counts.get('guestrin_valid', total)}, "
                     f"Blignaut {counts.get('blignaut_fixations', 0) - counts.get('blignaut_valid', 0)}"))
    return [_row("setting", "value"), _row("---", "---")] + [_row(k, v) for k, v in rows]


def _profiles_section(s: dict[str, Any]) -> list[str]:
    c, g = s.get("guestrin_compare"), s["guestrin"]
    if not c:
        return []
    lines = ["", f"## Estimator profiles: {g['profile']} vs {c['profile']} on the same features", "",
             "A finding beyond the paper: how much of the published Guestrin error was the estimator's. Both "
             "profiles calibrate the same ray-traced features; only the host estimator differs "
             "(`eyehil.drivers.gaze.guestrin.PROFILES`).", "",
             _row("profile", "H1 mean +- SD (skew)", "H2 mean +- SD (skew)", "Q_ac coefficient H1 / H2 (deg/SD)",
                  "significant (multivariate) H1", "R^2 H1"), _row(*["---"] * 6)]
    for name, block, sens in ((g["profile"], g, s["sensitivity"]), (c["profile"], c, c["sensitivity"])):
        q = [sens[k]["coefficients"].get("Q_ant_cornea", {}).get("coef", float("nan")) for k in ("H1", "H2")]
        lines.append(_row(name, *(f"{block[k]['mean']:.3f} +- {block[k]['sd']:.3f} ({block[k]['skewness']:.2f})"
                                  for k in ("H1", "H2")), f"{q[0]:+.3f} / {q[1]:+.3f}",
                          ", ".join(sens["H1"]["significant"]) or "none", f"{sens['H1']['r_squared']:.3f}"))
    ratio = c["H1"]["mean"] / g["H1"]["mean"]
    lines += ["", f"The {c['profile']} estimator's H1 is {ratio:.2f}x the {g['profile']} one's: "
              f"{100 * (1 - ratio):.0f}% of the replicated published-level error comes from the estimator, not "
              "from the eyes or the optics."]
    return lines


def _anatomy_section(s: dict[str, Any]) -> list[str]:
    a = s.get("anatomy")
    if not a:
        return []
    lines = ["", "## Paper vs full anatomy (the same eyes)", "",
             "A finding beyond the paper: the same eyes, seed and scenes with the anatomy the study left out "
             "(`eyehil.emulator.eye.anatomy.full_anatomy`: astigmatism drawn conditionally on each eye's parameters, "
             "pupil decentration, elliptical stop, cornea tilt). Errors in degrees; significant parameters of the "
             "multivariate regression (p < .05, strongest first).", "",
             _row("error", "paper mean +- SD", "full mean +- SD", "change of mean / SD", "significant (paper)",
                  "significant (full)"), _row(*["---"] * 6)]
    for col, r in a.items():
        p, f = r["paper"], r["full"]
        lines.append(_row(col, f"{p['mean']:.3f} +- {p['sd']:.3f}", f"{f['mean']:.3f} +- {f['sd']:.3f}",
                          f"{f['mean'] - p['mean']:+.3f} / {f['sd'] - p['sd']:+.3f}",
                          ", ".join(p["significant"]) or "none", ", ".join(f["significant"]) or "none"))
    return lines


def _breakdown_section(s: dict[str, Any]) -> list[str]:
    b = s.get("anatomy_breakdown")
    if not b:
        return []
    labels = list(COMPONENTS.values())
    lines = ["", "## Which added anatomy moves the errors", "",
             "The same eyes with each addition of the full anatomy alone (the deviates it has in the full run; "
             "`eyehil.analysis.study.breakdown`). Change of the mean error from the paper anatomy (deg); the "
             "interaction is what the additions do only together, so paper + the changes + interaction = full.", "",
             _row("error", "paper mean", *(f"+ {c}" for c in labels), "interaction", "full mean", "moves it most"),
             _row(*["---"] * (len(labels) + 5))]
    for col, r in b.items():
        most = f"none ({COMPONENTS[r['largest_change']]}: < {NEGLIGIBLE_DEG} deg)" if r["negligible"] else \
            COMPONENTS[r["largest_change"]]
        lines.append(_row(col, f"{r['runs']['paper']['mean']:.3f}", *(_change(r["change"][c]) for c in COMPONENTS),
                          _change(r["interaction"]), f"{r['runs']['full']['mean']:.3f}", most))
    lines += ["", "SD of the error over the eyes (deg), each addition alone:", "",
              _row("error", "paper", *labels, "full"), _row(*["---"] * (len(labels) + 3))]
    for col, r in b.items():
        lines.append(_row(col, *(f"{r['runs'][k]['sd']:.3f}" for k in ("paper", *COMPONENTS, "full"))))
    lines += ["", "Where the full anatomy's between-subject spread comes from: the share of the variance of each eye's "
              "error explained by each group of per-eye parameters (the Shapley/LMG split of the R^2 of a linear "
              "regression on the study's 11 parameters, the astigmatism J0, J45, |J| of both corneal surfaces and "
              "the pupil's nasal, superior and total decentration; the shares sum to R^2). The elliptical stop and "
              "the cornea tilt are the same in every eye: they move the mean but explain no spread.", "",
              _row("error", "SD (full)", *(f"{g} (%)" for g in GROUPS), "unexplained (%)", "R^2", "eyes"),
              _row(*["---"] * (len(GROUPS) + 5))]
    for col, r in b.items():
        v = r["variance"]
        if "skipped" in v:
            lines.append(_row(col, f"{r['runs']['full']['sd']:.3f}", *(["-"] * len(GROUPS)), "-", "-", v["skipped"]))
            continue
        lines.append(_row(col, f"{np.sqrt(v['variance']):.3f}", *(f"{100 * v['shares'][g]:.0f}" for g in GROUPS),
                          f"{100 * v['unexplained']:.0f}", f"{v['r_squared']:.2f}", v["eyes"]))
    lines += ["", "In words:", ""] + [_breakdown_sentence(col, r) for col, r in b.items()]
    return lines


def _change(value: float) -> str:
    """A change in deg with its sign, "0.000" when it rounds to zero (no "-0.000")."""
    return "0.000" if round(value, 3) == 0 else f"{value:+.3f}"


def _breakdown_sentence(col: str, r: dict[str, Any]) -> str:
    """What moves the mean of one error category most and what explains most of its spread (a list item)."""
    c = r["largest_change"]
    if r["negligible"]:
        text = (f"- {col}: no addition moves the mean by {NEGLIGIBLE_DEG} deg or more (full - paper "
                f"{_change(r['total_change'])})")
    else:
        text = (f"- {col}: {COMPONENTS[c]} moves the mean most ({_change(r['change'][c])} deg of "
                f"{_change(r['total_change'])} full - paper)")
    v = r["variance"]
    if "shares" in v:
        added = {g: v["shares"][g] for g in GROUPS if g != GROUPS[0]}
        top = max(added, key=added.get)
        text += (f"; of its spread between subjects (SD {np.sqrt(v['variance']):.3f} deg) {top} explains "
                 f"{100 * added[top]:.0f}%, the paper anatomy {100 * v['shares'][GROUPS[0]]:.0f}%")
    return text + "."


def _univariate_table(s: dict[str, Any]) -> list[str]:
    lines = ["", "## Sensitivity, univariate (one parameter at a time, as the study's code ran it; deg per SD)", "",
             _row("error", "significant (p < .05): coefficient (R^2)"), _row("---", "---")]
    for col, r in s["sensitivity"].items():
        uni = r.get("univariate", {})
        lines.append(_row(col, ", ".join(f"{n} {uni[n]['coef']:+.3f} ({uni[n]['r_squared']:.2f})"
                                         for n in r.get("significant_univariate", [])) or "none"))
    others = [r["univariate"][n]["r_squared"] for r in s["sensitivity"].values()
              for n in r.get("significant_univariate", []) if n != "Q_ant_cornea"]
    if others:
        lines += ["", f"Parameters other than Q_ac that reach p < .05 alone explain at most {100 * max(others):.0f}% "
                  "of the variance each (Q_ac alone: most of it); where the multivariate regression of the paper's "
                  "text does not keep them, their univariate effect is the part they share with Q_ac in these eyes."]
    return lines


def _departures(s: dict[str, Any]) -> list[str]:
    """Every remaining departure from the published study, with numbers."""
    lines = ["", "## Remaining departures", ""]
    items = [f"- {f.claim}: replicated {f.replicated}." for f in all_findings(s) if not f.holds]
    g = s["guestrin"]
    pub = fischer_simulated()
    for k in ("H1", "H2"):
        items.append(f"- Guestrin {k} mean {g[k]['mean']:.3f} vs published {pub[k]['mean']} deg "
                     f"({g[k]['mean'] - pub[k]['mean']:+.3f}); SD {g[k]['sd']:.3f} vs {pub[k]['sd']} "
                     f"({g[k]['sd'] - pub[k]['sd']:+.3f}).")
    items.append("- Calibration optimiser: the study's fmincon (interior point, default tolerances) is replaced by a "
                 "Levenberg-Marquardt on the same objective and bounds, converged tightly; fmincon's stopping point "
                 "is not reproducible, so per-eye errors can differ where the objective is flat.")
    items.append("- Blignaut models 9-12 (forms X9, Y8, Y9 of the 2014 paper) are not available, and fits with fewer "
                 "targets than terms (C5, models 3, 4, 7, 8) fail explicitly where the published table lists values.")
    return lines + items
