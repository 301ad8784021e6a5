"""Figures of the replication report (matplotlib's object API: no pyplot state, no display).

Each function takes plain arrays and the summary, writes one figure as a PNG at `DPI` and an SVG beside it
(same name, `.svg`) and returns the PNG's path (`svg_of` gives the other).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from scipy import stats as sps

from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.analysis.study.stats import partial_regression, zscore_columns


def _figure(rows: int, cols: int, size: tuple[float, float]):
    fig = Figure(figsize=size)
    return fig, fig.subplots(rows, cols, squeeze=False)


DPI = 200
#: Readable names (with units) of the parameter keys of `population.STUDY_KEYS` / `TABLE4_KEYS`.
LABELS = {
    "R_ant_cornea_mm": "R_ac, anterior corneal radius (mm)", "Q_ant_cornea": "Q_ac, anterior corneal asphericity",
    "R_post_cornea_mm": "R_pc, posterior corneal radius (mm)", "Q_post_cornea": "Q_pc, posterior corneal asphericity",
    "R_lens_ant_mm": "R_la, anterior lens radius (mm)", "R_lens_post_mm": "|R_lp|, posterior lens radius (mm)",
    "CCT_mm": "CCT, central corneal thickness (mm)", "ACD_mm": "ACD from the posterior cornea (mm)",
    "ACD_from_anterior_cornea_mm": "ACD from the anterior cornea (mm)", "lens_thickness_mm": "lens thickness (mm)",
    "axial_length_mm": "axial length (mm)", "pupil_diameter_mm": "pupil diameter (mm)",
    "n_lens": "n_lens, lens refractive index",
}


def svg_of(png: Path) -> Path:
    """The SVG written beside a figure's PNG."""
    return png.with_suffix(".svg")


def _save(fig: Figure, path: Path, rect: tuple[float, float, float, float] | None = (0.0, 0.0, 1.0, 1.0)) -> Path:
    """Write the PNG and the SVG; `rect` is tight_layout's, None for a figure laid out already (`_grid_margins`:
    the multi-panel figures, where tight_layout costs as much as drawing them)."""
    if rect is not None:
        fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=DPI)
    with rc_context({"svg.fonttype": "none"}):  # text stays text (searchable, and 3x faster than paths)
        fig.savefig(svg_of(path))
    return path


def _grid_margins(fig: Figure, top_in: float, bottom_in: float, left_in: float, hspace: float,
                  wspace: float) -> None:
    """Fixed margins in inches (top: suptitle and panel titles; bottom: x label; left: y label and ticks)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left_in / w, right=1 - 0.15 / w, top=1 - top_in / h, bottom=bottom_in / h,
                        hspace=hspace, wspace=wspace)


def signed(value: float, digits: int = 3) -> str:
    """`value` with sign and `digits` decimals, never "-0.000": values that round to zero get significant digits."""
    if value != 0 and round(value, digits) == 0:
        return f"{value:+.1e}"
    return f"{value + 0.0:+.{digits}f}"


def _ci95(values: np.ndarray) -> float:
    v = values[np.isfinite(values)]
    return float(sps.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))


def table4(params: dict[str, np.ndarray], published: dict[str, list[float]], path: Path) -> Path:
    """Histogram of each eye parameter with the published mean +- SD (Table 4)."""
    names = list(params)
    fig, axes = _figure(3, 4, (13, 8.4))
    for ax, name in zip(axes.ravel(), names, strict=False):
        values = np.asarray(params[name], dtype=float)
        if np.ptp(values) <= 1e-9 * max(1.0, abs(float(values.mean()))):  # one value for every eye
            ax.bar([values.mean()], [values.size], width=0.002 * max(abs(float(values.mean())), 1.0),
                   color="#4c72b0", alpha=0.8)
            ax.set_ylim(0, 1.3 * values.size)
            ax.text(0.03, 0.97, f"{values.mean():.3f} in every eye", transform=ax.transAxes, va="top", fontsize=8)
        else:
            ax.hist(values, bins=15, color="#4c72b0", alpha=0.8, label="replicated eyes")
        if name in published:
            m, sd = published[name]
            ax.axvline(m, color="k", label="published mean")
            ax.axvspan(m - sd, m + sd, color="k", alpha=0.1, label="published mean +- SD")
        if np.ptp(values) <= 1e-9 * max(1.0, abs(float(values.mean()))):
            half = max(4.0 * (published.get(name, [0.0, 0.0])[1] or 0.0), 0.02 * abs(float(values.mean())), 0.01)
            ax.set_xlim(values.mean() - half, values.mean() + half)
        ax.set_xlabel(LABELS.get(name, name), fontsize=8)
        ax.set_ylabel("eyes", fontsize=8)
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.suptitle(f"Eye parameters of the {len(next(iter(params.values())))} simulated eyes (Table 4)")
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=9, frameon=False)
    _grid_margins(fig, top_in=0.55, bottom_in=0.8, left_in=0.6, hspace=0.42, wspace=0.3)
    return _save(fig, path, rect=None)


def features(pupil: np.ndarray, glint: np.ndarray, labels: list[str], path: Path, title: str = "") -> Path:
    """Fig. 3: pupil centres (a) and glint centres (b) over the targets for two contrasting eyes (px)."""
    fig, axes = _figure(1, 2, (11, 4.8))
    if title:
        fig.suptitle(title, fontsize=10)
    a, b = axes[0]
    for i, label in enumerate(labels):
        a.plot(pupil[i, :, 0], pupil[i, :, 1], "o", ms=3, label=label)
        b.plot(glint[i, :, 0], glint[i, :, 1], "o", ms=3, label=label)
    for ax, title in ((a, "(a) pupil centre"), (b, "(b) glint centre")):
        ax.set_title(title)
        ax.set_xlabel("image x (px)")
        ax.set_ylabel("image y (px)")
        ax.invert_yaxis()
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8)
    return _save(fig, path)


def guestrin(h: dict[str, np.ndarray], real: dict[str, np.ndarray], published: dict[str, Any], path: Path) -> Path:
    """Fig. 4: H1 and H2, simulated vs real, means with 95% confidence intervals."""
    fig, axes = _figure(1, 1, (6.5, 4.5))
    ax = axes[0, 0]
    for j, key in enumerate(("H1", "H2")):
        sim, rl = h[key], real[key]
        ax.errorbar(j - 0.15, np.nanmean(sim), yerr=_ci95(sim), fmt="o", color="#4c72b0", capsize=4,
                    label="replicated" if j == 0 else None)
        ax.errorbar(j + 0.15, rl.mean(), yerr=_ci95(rl), fmt="s", color="#dd8452", capsize=4,
                    label="real (Guestrin 2006)" if j == 0 else None)
        ax.plot(j, published[key]["mean"], "k^", label="published simulation" if j == 0 else None)
        ax.plot(np.full(sim.size, j - 0.3) + np.linspace(-0.05, 0.05, sim.size), sim, ".", color="#4c72b0", alpha=0.3,
                label="replicated, per eye" if j == 0 else None)
    ax.set_xticks([0, 1], ["H1 (central)", "H2 (moved head)"])
    ax.set_ylabel("mean gaze error (deg)")
    ax.legend(fontsize=8)
    ax.set_title("Guestrin & Eizenman 2006: simulated vs real (95% CI)")
    return _save(fig, path)


def blignaut(best: dict[str, np.ndarray], real_best: dict[str, float], models: dict[str, int], path: Path) -> Path:
    """Fig. 6: best-function error per configuration, simulated (mean, 95% CI, spread) vs real."""
    fig, axes = _figure(1, 1, (8, 5))
    ax = axes[0, 0]
    x = np.arange(len(CONFIGURATIONS))
    sim = [np.asarray(best[c], dtype=float) for c in CONFIGURATIONS]
    blue = "#4c72b0"
    ax.boxplot([v[np.isfinite(v) & (v > 0)] for v in sim], positions=x, widths=0.35, showfliers=True,
               medianprops={"color": blue}, flierprops={"marker": ".", "markeredgecolor": blue, "alpha": 0.5})
    ax.plot([], [], "s", mfc="none", mec="k", ms=9, label="replicated eyes (box: quartiles and median)")
    ax.errorbar(x, [np.nanmean(v) for v in sim], yerr=[_ci95(v) for v in sim], fmt="o", color=blue, capsize=4,
                label="replicated mean (95% CI)")
    ax.plot(x, [real_best[c] for c in CONFIGURATIONS], "s-", color="#dd8452", label="real best function (mean)")
    ax.set_yscale("log")  # the replicated errors lie 10-30x below the real ones: a linear axis squashes them
    low, high = ax.get_ylim()
    ax.set_ylim(low, high * 2.5)  # room for the legend above the data
    ticks = [t for t in (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0) if low <= t <= high * 2.5]
    ax.set_yticks(ticks, [f"{t:g}" for t in ticks])
    ax.minorticks_off()
    ax.set_xticks(x, [f"{c}\n(model {models[c]})" for c in CONFIGURATIONS])
    ax.set_ylabel("best-function error (deg, log scale)")
    ax.grid(True, which="major", axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title("Blignaut 2014: best-function error per calibration configuration")
    return _save(fig, path)


def sensitivity(X: np.ndarray, names: list[str], columns: dict[str, np.ndarray], sens: dict[str, Any],
                path: Path, title: str) -> Path:
    """Figs. 5 and 7: partial-regression plot of the strongest significant parameter of each error column."""
    Z = zscore_columns(X)
    ncols = min(3, len(columns))
    nrows = -(-len(columns) // ncols)
    fig, axes = _figure(nrows, ncols, (4.0 * ncols, 3.4 * nrows))
    for ax, (col, y) in zip(axes.ravel(), columns.items(), strict=False):
        sig = sens[col]["significant"]
        if not sig:
            ax.set_title(f"{col}: nothing significant")
            continue
        keep = [names.index(n) for n in sig]
        design = np.column_stack([np.ones(len(y)), Z[:, keep]])
        pr = partial_regression(design, y, 1)
        ax.plot(pr.x, pr.y, ".", alpha=0.6)
        xs = np.linspace(pr.x.min(), pr.x.max(), 2)
        ax.plot(xs, pr.slope * xs, "k-")
        full = sens[col]["coefficients"][sig[0]]["coef"]  # the report's number (the fit on all 11)
        ax.set_title(f"{col}: {sig[0]} {full:+.3f} deg/SD (all 11)\n"
                     f"{pr.slope:+.3f} refit on the significant, R² = {sens[col]['r_squared']:.2f}", fontsize=8)
        ax.set_xlabel(f"{sig[0]} (z, partial)")
        ax.set_ylabel("error (deg, partial)")
    for ax in axes.ravel()[len(columns):]:
        ax.axis("off")
    fig.suptitle(title)
    _grid_margins(fig, top_in=0.95, bottom_in=0.5, left_in=0.75, hspace=0.55, wspace=0.32)
    return _save(fig, path, rect=None)


def profiles(h1: dict[str, np.ndarray], q_ac: np.ndarray, sens: dict[str, dict[str, Any]], path: Path) -> Path:
    """Fig. 8 (beyond the paper): the same eyes' H1 under two estimator profiles, and H1 against Q_ac.

    h1: {profile: per-eye H1 (deg)} (first = the replication's profile); sens: {profile: its H1
    sensitivity summary}, for the Q_ac coefficient (deg per SD) printed in the legend.
    """
    (a_name, a), (b_name, b) = list(h1.items())[:2]
    fig, axes = _figure(1, 2, (11, 4.5))
    ax, bx = axes[0]
    ax.plot(b, a, ".", alpha=0.7)
    top = float(np.nanmax([np.nanmax(a), np.nanmax(b)])) * 1.05
    ax.plot([0, top], [0, top], "k:", lw=1, label="equal")
    ax.set_xlabel(f"H1, {b_name} (deg)")
    ax.set_ylabel(f"H1, {a_name} (deg)")
    ax.set_title("(a) the same eyes, two estimators")
    ax.legend(fontsize=8)
    for name, values in h1.items():
        coef = sens[name]["H1"]["coefficients"].get("Q_ant_cornea", {}).get("coef", float("nan"))
        bx.plot(q_ac, values, ".", alpha=0.7,
                label=f"{name}: mean {np.nanmean(values):.3f} deg, Q_ac {coef:+.3f} deg/SD")
    bx.set_xlabel("Q_ac (anterior corneal asphericity)")
    bx.set_ylabel("H1 (deg)")
    bx.set_title("(b) H1 against corneal asphericity")
    bx.legend(fontsize=8)
    fig.suptitle("Guestrin: how much of the error is the estimator's")
    return _save(fig, path)


def anatomy(X: np.ndarray, names: list[str], h1: dict[str, np.ndarray], significant: list[str], path: Path,
            column: str) -> Path:
    """Fig. 9 (beyond the paper): partial regression of H1 on each significant parameter of the full-anatomy run.

    h1: {"paper": per-eye H1, "full": per-eye H1} (deg) of the same eyes; X: the full run's study parameters
    (eyes, 11); significant: the full run's significant parameters (strongest first). Each panel plots the
    partial residuals of H1 against one parameter (z-scored), controlling for the other significant ones.
    """
    Z = zscore_columns(X)
    shown = significant or names[:1]
    ncols = min(3, len(shown))
    nrows = -(-len(shown) // ncols)
    fig, axes = _figure(nrows, ncols, (max(4.0 * ncols, 6.5), 3.4 * nrows + 0.6))
    keep = [names.index(n) for n in shown]
    for j, (ax, name) in enumerate(zip(axes.ravel(), shown, strict=False)):
        for label, y in h1.items():
            ok = np.isfinite(y)
            design = np.column_stack([np.ones(int(ok.sum())), Z[ok][:, keep]])
            pr = partial_regression(design, y[ok], j + 1)
            xs = np.linspace(pr.x.min(), pr.x.max(), 2)
            line = ax.plot(pr.x, pr.y, ".", alpha=0.6, label=f"{label} anatomy: {pr.slope:+.3f} deg/SD")[0]
            ax.plot(xs, pr.slope * xs, "-", color=line.get_color())
        ax.set_title(name if significant else f"{name} (nothing significant)", fontsize=9)
        ax.set_xlabel(f"{name} (z, partial)")
        ax.set_ylabel(f"{column} (deg, partial)")
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(shown):]:
        ax.axis("off")
    fig.suptitle(f"Paper vs full anatomy, the same eyes: partial regression of {column}\n"
                 "on each significant parameter of the full-anatomy run", fontsize=10)
    return _save(fig, path)


def breakdown(b: dict[str, Any], components: dict[str, str], groups: tuple[str, ...], path: Path) -> Path:
    """Fig. 10 (beyond the paper): which added anatomy moves each error category.

    b: `summary["anatomy_breakdown"]` {category: {change: {component: deg}, interaction, variance: {shares,
    unexplained}}}; (a) the change of the mean error by each addition alone and their interaction (deg),
    (b) the share of the full anatomy's between-subject variance explained by each parameter group (%)."""
    cols = list(b)
    y = np.arange(len(cols))
    fig, axes = _figure(1, 2, (13, 0.45 * len(cols) + 3.0))
    ax, bx = axes[0]
    names = [*components, "interaction"]
    height = 0.8 / len(names)
    colours = ["#c44e52", "#4c72b0", "#8172b2", "#55a868", "#999999"]
    for i, name in enumerate(names):
        values = [b[c]["interaction"] if name == "interaction" else b[c]["change"][name] for c in cols]
        ax.barh(y - 0.4 + (i + 0.5) * height, values, height, color=colours[i % len(colours)],
                label=components.get(name, name) + (" (alone)" if name in components else ""))
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_yticks(y, cols)
    ax.invert_yaxis()
    ax.set_xlabel("change of the mean error from the paper anatomy (deg)")
    ax.set_title("(a) each addition alone", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=3, frameon=False)
    ax.grid(True, axis="x", alpha=0.3)
    left = np.zeros(len(cols))
    shade = {groups[0]: "#dd8452", groups[1]: "#c44e52", groups[2]: "#4c72b0"}
    for g in [*groups, "unexplained"]:
        share = np.array([100 * (b[c]["variance"].get("shares", {}).get(g, np.nan) if g != "unexplained"
                                 else b[c]["variance"].get("unexplained", np.nan)) for c in cols])
        bx.barh(y, np.nan_to_num(share), 0.6, left=left, color=shade.get(g, "#dddddd"), label=g, edgecolor="white")
        left += np.nan_to_num(share)
    for yi, c in zip(y, cols, strict=True):
        if "skipped" in b[c]["variance"]:
            bx.text(1, yi, "not enough eyes", va="center", fontsize=8)
    bx.set_xlim(0, 100)
    bx.set_yticks(y, cols)
    bx.invert_yaxis()
    bx.set_xlabel("share of the between-subject variance, full anatomy (%)")
    bx.set_title("(b) where the spread comes from (Shapley split of R²)", fontsize=10)
    bx.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=4, frameon=False)
    fig.suptitle("Which added anatomy moves the errors (the same eyes, --anatomy full)")
    return _save(fig, path)
