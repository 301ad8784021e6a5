"""Figures of the replication report (PNG via matplotlib's object API: no pyplot state, no display).

Each function takes plain arrays and the summary, writes one file and returns its path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from scipy import stats as sps

from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.analysis.study.stats import partial_regression, zscore_columns


def _figure(rows: int, cols: int, size: tuple[float, float]):
    fig = Figure(figsize=size)
    return fig, fig.subplots(rows, cols, squeeze=False)


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _ci95(values: np.ndarray) -> float:
    v = values[np.isfinite(values)]
    return float(sps.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))


def table4(params: dict[str, np.ndarray], published: dict[str, list[float]], path: Path) -> Path:
    """Histogram of each eye parameter with the published mean +- SD (Table 4)."""
    names = list(params)
    fig, axes = _figure(3, 4, (13, 8))
    for ax, name in zip(axes.ravel(), names, strict=False):
        ax.hist(params[name], bins=15, color="#4c72b0", alpha=0.8)
        if name in published:
            m, s = published[name]
            ax.axvline(m, color="k")
            ax.axvspan(m - s, m + s, color="k", alpha=0.1, label="published mean +- SD")
        ax.set_title(name, fontsize=9)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Eye parameters of the simulated eyes (Table 4)")
    return _save(fig, path)


def features(pupil: np.ndarray, glint: np.ndarray, labels: list[str], path: Path) -> Path:
    """Fig. 3: pupil centres (a) and glint centres (b) over the targets for two contrasting eyes (px)."""
    fig, axes = _figure(1, 2, (11, 4.5))
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
        ax.plot(np.full(sim.size, j - 0.3) + np.linspace(-0.05, 0.05, sim.size), sim, ".", color="#4c72b0", alpha=0.3)
    ax.set_xticks([0, 1], ["H1 (central)", "H2 (moved head)"])
    ax.set_ylabel("mean gaze error (deg)")
    ax.legend(fontsize=8)
    ax.set_title("Guestrin & Eizenman 2006: simulated vs real (95% CI)")
    return _save(fig, path)


def blignaut(best: dict[str, np.ndarray], real_best: dict[str, float], models: dict[str, int], path: Path) -> Path:
    """Fig. 6: best-function error per configuration, simulated (mean, 95% CI, spread) vs real."""
    fig, axes = _figure(1, 1, (8, 4.5))
    ax = axes[0, 0]
    x = np.arange(len(CONFIGURATIONS))
    sim = [best[c] for c in CONFIGURATIONS]
    ax.boxplot(sim, positions=x, widths=0.35, showfliers=True)
    ax.errorbar(x, [np.nanmean(v) for v in sim], yerr=[_ci95(v) for v in sim], fmt="o", capsize=4,
                label="replicated mean (95% CI)")
    ax.plot(x, [real_best[c] for c in CONFIGURATIONS], "s-", color="#dd8452", label="real best function")
    ax.set_xticks(x, [f"{c}\n(model {models[c]})" for c in CONFIGURATIONS])
    ax.set_ylabel("best-function error (deg)")
    ax.legend(fontsize=8)
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
        ax.set_title(f"{col}: {sig[0]} {pr.slope:+.3f} deg/SD\nR2 = {sens[col]['r_squared']:.2f}", fontsize=9)
        ax.set_xlabel(f"{sig[0]} (z, partial)")
        ax.set_ylabel("error (deg, partial)")
    fig.suptitle(title)
    return _save(fig, path)
