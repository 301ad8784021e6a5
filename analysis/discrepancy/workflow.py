"""The discrepancy workflow: find where simulation and measured data disagree, name the missing effect,
add it to the model, and show the gap shrink.

1. find (`find`): simulate the experiment of the measured data on a set of search eyes with the current
   model, and test every measured condition (`eyehil.analysis.discrepancy.stats`: Welch or one-sample t,
   Holm-adjusted, gap measure D = sum t^2). No significant condition: stop, nothing is added.
2. name (`name_effects`): for every effect of the registry (`eyehil.emulator.effects`) that can act in this
   experiment and is not in the model yet, fit its parameters to minimise D (`eyehil.analysis.discrepancy.search`),
   and rank the effects by D + 2k (k fitted parameters).
3. add: the best-ranked effect joins the model at its fitted values if it lowers D by more than the
   chi-square(k) 95 % point (after the misfit scale factor, `EffectFit.passes`); otherwise the gap is
   reported as unexplained by the registry.
   Steps 1-3 repeat for up to `rounds` rounds.
4. show (`run_discrepancy`): the comparison before and after, on the (usually larger) show eyes, which
   checks that what was fitted on the search eyes carries over.

`hidden_measured` makes "measured" data by simulating other eyes with a hidden effect, for testing the
workflow blind (tests/test_discrepancy.py, `eyehil discrepancy --hidden`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eyehil.analysis.discrepancy.data import Measured, MeasuredCondition
from eyehil.analysis.discrepancy.metrics import Evaluator
from eyehil.analysis.discrepancy.search import EffectFit, search_effects
from eyehil.analysis.discrepancy.stats import Comparison, compare
from eyehil.emulator import effects as registry
from eyehil.emulator.effects import Applied, Effect
from eyehil.emulator.eye.model import EyeModel


@dataclass(frozen=True, eq=False)
class Round:
    """One find-name-add round on the search eyes."""

    before: Comparison
    fits: list[EffectFit]  # ranked, best first
    added: EffectFit | None
    verdict: str


@dataclass(eq=False)
class DiscrepancyResult:
    """The rounds, the effects added, and the show comparison before and after."""

    measured: Measured
    rounds: list[Round]
    added: list[Applied]
    before: Comparison
    after: Comparison
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def shrink(self) -> float:
        """1 - D_after / D_before on the show eyes (0 when nothing was added)."""
        return 1.0 - self.after.D / self.before.D if self.before.D > 0 else 0.0


def find(evaluator: Evaluator, measured: Measured, alpha: float = 0.05) -> Comparison:
    """Step 1: the current model's gaps."""
    return compare(evaluator.base_metrics, measured, evaluator.experiment.reference, alpha)


def candidates(evaluator: Evaluator, names: Sequence[str] | None = None) -> list[Effect]:
    """Registered effects that can act in this experiment and are not in the model yet."""
    present = {a.effect.name for a in evaluator.base}
    chosen = [registry.get(n) for n in (names or registry.names())]
    one_session = len(evaluator.host.head_positions) < 2
    return [e for e in chosen if e.name not in present and not (e.validation_only and one_session)]


def name_effects(evaluator: Evaluator, measured: Measured, before: Comparison, effect_names=None,
                 alpha: float = 0.05, progress: Callable[[int], None] | None = None) -> list[EffectFit]:
    """Step 2: every candidate effect fitted (batched together), ranked by D + 2k (best first)."""

    def gap(batch: list[Applied]) -> np.ndarray:
        metrics = evaluator.evaluate([[a] for a in batch], progress)
        return np.array([compare(m, measured, evaluator.experiment.reference, alpha).D for m in metrics])

    fits = search_effects(candidates(evaluator, effect_names), gap, before.D, len(before.gaps))
    return sorted(fits, key=lambda f: f.score)


def run_discrepancy(measured: Measured, *, eyes: EyeModel, search_eyes: EyeModel | None = None,
                    effect_names: Sequence[str] | None = None, rounds: int = 2, alpha: float = 0.05,
                    seed: int = 0, workers: int = 1,
                    progress: Callable[[int], None] | None = None) -> DiscrepancyResult:
    """The whole workflow (module docstring); `search_eyes` defaults to `eyes`; `workers` > 1 evaluates the
    points of each search stage in that many processes."""
    with ProcessPoolExecutor(workers) if workers > 1 else nullcontext() as pool:
        search = initial = Evaluator(measured.experiment, search_eyes if search_eyes is not None else eyes,
                                     seed=seed, pool=pool, workers=workers)
        done, added = [], []
        for _ in range(rounds):
            current = _round(search, measured, effect_names, alpha, progress)
            done.append(current)
            if current.added is None:
                break
            added.append(current.added.applied)
            search = search.with_base(added)
        if search_eyes is None:
            show_before, show_after = initial, search
        else:
            show_before = Evaluator(measured.experiment, eyes, seed=seed, pool=pool, workers=workers)
            show_after = show_before.with_base(added) if added else show_before
    settings = {"experiment": measured.experiment, "eyes": len(show_before.eyes), "search_eyes": len(initial.eyes),
                "rounds": rounds, "alpha": alpha, "seed": seed,
                "evaluations": sum(len(f.points) for r in done for f in r.fits)}
    return DiscrepancyResult(measured, done, added, find(show_before, measured, alpha),
                             find(show_after, measured, alpha), settings)


def _round(search: Evaluator, measured: Measured, effect_names, alpha, progress) -> Round:
    """Steps 1-3 once."""
    before = find(search, measured, alpha)
    if not before.significant:
        return Round(before, [], None, "no significant gap: nothing to add")
    fits = name_effects(search, measured, before, effect_names, alpha, progress)
    best = fits[0] if fits and fits[0].passes() else None
    return Round(before, fits, best, _verdict(best, fits))


def _verdict(best: EffectFit | None, fits: list[EffectFit]) -> str:
    if best is not None:
        return f"added {best.applied.label()}: D {best.D0:.1f} -> {best.D:.1f}"
    if not fits:
        return "no candidate effect left"
    top = fits[0]
    return (f"no effect explains the gap: the best, {top.applied.label()}, lowers D by {top.reduction:.2f}, "
            f"{top.reduction / top.scale**2:.2f} after the misfit scale (needs > the chi-square({top.k}) 95 % point)")


def hidden_measured(hidden: Sequence[Applied], *, eyes: EyeModel, experiment: str = "guestrin2006",
                    conditions: Sequence[str] | None = None, seed: int = 1) -> Measured:
    """Per-subject "measured" conditions of `eyes` simulated with `hidden` effects (noise seed `seed`)."""
    evaluator = Evaluator(experiment, eyes, base=hidden, seed=seed)
    names = tuple(conditions or evaluator.experiment.diagnostic_conditions(evaluator.host))
    values = np.array([evaluator.base_metrics[c] for c in names])
    keep = np.all(np.isfinite(values), axis=0)
    subjects = tuple(f"eye{i + 1}" for i in np.flatnonzero(keep))
    data = {c: MeasuredCondition.of(v[keep]) for c, v in zip(names, values, strict=True)}
    labels = [a.label() for a in hidden] or ["none"]
    return Measured(experiment, data, subjects, f"simulated: {len(subjects)} eyes, hidden {', '.join(labels)}",
                    {"hidden": labels})
