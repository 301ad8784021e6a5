"""The discrepancy workflow: find where simulation and measured data disagree, name the missing effect(s),
add them to the model, and show the gap shrink, or say that no known effect explains it. A round's steps 1-3 live
in `eyehil.analysis.discrepancy.rounds`, with the outcome's criterion (`decide`); the refits of the added effects
together and the other effects tried in their places in `eyehil.analysis.discrepancy.refit`; this module runs
them in order (`run_discrepancy`) and shows the result.

1. find (`find`): simulate the experiment of the measured data on the search eyes with the current model
   and test every measured condition's mean and spread (`eyehil.analysis.discrepancy.stats`: permutation tests,
   Holm adjusted; gap measure D = sum of squared normal scores of the mean and spread terms). Where no condition
   is significant, D itself is tested (`Round.diffuse_p`: the goodness of fit of the current model, the permutation
   test of `eyehil.analysis.discrepancy.stats.permutation_gof` where every condition has per-subject values, else
   chi-square(n_terms - k) for the k parameters fitted so far) at the same alpha: an effect spread thinly over
   every condition (a corneal asphericity beside a camera bump that took up most of its gap) leaves no condition
   significant but D beyond chance. No significant gap either way: stop.
2. name (`name_effects`): every effect of the catalogue (`eyehil.emulator.effects`) that can act in this
   experiment and is not in the model yet is fitted to minimise D (`eyehil.analysis.discrepancy.search`: a
   screen of all, refinement of the best few) and ranked by D + 2k (k fitted parameters), in every round
   (not only those that lowered D in round 1: that hides a pair's smaller effect, whose drop of D in round 1
   is scaled down by the larger one's misfit). From round 2 on, every candidate's point is scored with the
   earlier rounds' effects free near their fits (`rounds.added_profile`, `eyehil.analysis.discrepancy.profile`: D
   minimised over a linear shift of their parameters), for their fits are biased by the gap still open when they
   were made.
3. add: the top-ranked effect with no fitted parameter at the edge of its plausible range joins the model at
   its fitted values if it lowers D by more than the chi-square(k) point at level 1 - `ALPHA_ADD` / n (after the
   misfit scale factor; `add_level`: Bonferroni over the n candidates fitted in the round, for the best of n is
   chosen after seeing the data; `EffectFit.passes`). A fit at an edge is evidence against its effect: it is
   reported and never added, and the next candidate is considered (the search refined it for that case). If
   nothing passes, nothing is added and the round says why.
   Steps 1-3 repeat for up to `rounds` rounds (a second effect is fitted with the first in the model).
   A later round whose best fit ends at an edge, or where nothing passes though a gap is left, is fitted again
   from other starts of the earlier effects: their screens' other basins, or their rounds' close contenders in
   their place (`refit.restart`: the earlier fits' bias can hold the round's effect at an edge or make it useless).
   With two or more effects added, each is refitted with the others in the model (`refit._backfit`), then all are
   moved together along their linear model while D falls (`refit._polish`: one effect at a time crawls along a valley
   where two trade off), and refitted again there (`refit.settle`); and so are every round's close contenders,
   the last round's first (`refit.contend`): up to `refit.CONTENDERS` refined fits that lower D and score within
   `refit.CONTEND` of the added one (after the added fit's misfit scale s^2), each backfitted in place of the
   effect its round added. The first effect was fitted while the second's gap was still open, so the round ranks
   the second's candidates against a biased first (a pupil decentration behind a corneal one, 93 against 76, that
   tie at 64 and 63 once the lens distortion fitted before them is refitted); the backfitted model of lowest
   D + 2k is kept, and the others within `RIVAL_SCORE` of it are its rivals.
4. show (`run_discrepancy`): the comparison before and after, on the (usually larger) show eyes.

The **outcome** (`DiscrepancyResult.outcome`) is decided by a stated criterion:

- "no gap": round 1 found no significant gap (no condition, nor D as a whole); nothing is added.
- "explained": effects were added, and with them (a) no significant gap is left on the search eyes nor
  on the show eyes, and (b) the model fits: goodness-of-fit p >= `ALPHA_GOF` on the search eyes (the
  permutation test of D of `eyehil.analysis.discrepancy.stats.permutation_gof` where every condition has
  per-subject values, else P(chi-square(n_terms - k_total) >= D)). `named_effects` lists them in the order of the size
  of what each explains alone (its own drop of D from the model without effects).
- "none explains": otherwise. Effects fitted on the way that lowered D are reported as partial, not
  named: a significant gap left after an addition means the addition did not explain the data. Before this
  verdict, each round's close contenders, screened ones too (up to `refit.ALTERNATIVES`), are tried in place of the
  effect it added, the model settled (`refit.explain`): a mimic can score best on the search eyes and still leave a
  gap the criterion sees. A model so made that meets (a) and (b) is kept ("explained"), of least D + 2k if more
  than one do, and its round's verdict says what it replaced and why.

With two or more effects added, `interactions` reports D with each alone, all together, and the
interaction D0 - D_all - sum_i (D0 - D_i) (0 when their contributions add; computed on the search eyes).

Whether the data can tell the candidates apart: each round's `rivals` are the other effects whose fit is as good
as the added one's (D + 2k within `RIVAL_SCORE`, the rule of thumb for two AICs: Burnham & Anderson 2002,
"Model selection and multimodel inference", section 2.6); `summary.json` lists them per added effect, and the
added effects' `twins` (`eyehil.emulator.effects.base`: effects that change every condition alike at matched
values, which no number of eyes tells apart).

`hidden_measured` makes "measured" data by simulating other eyes with hidden effects, for testing the
workflow blind (tests/test_discrepancy*.py, `eyehil discrepancy --hidden`).
"""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from eyehil.analysis.discrepancy.data import Measured, MeasuredCondition
from eyehil.analysis.discrepancy.metrics import Evaluator, Memo
from eyehil.analysis.discrepancy.refit import contend, drop_off, explain, restart, settle
from eyehil.analysis.discrepancy.rounds import (
    ALPHA_GOF,
    Progress,
    Round,
    Silent,
    added_profile,
    decide,
    find,
    goodness_of_fit,
    run_round,
)
from eyehil.analysis.discrepancy.search import EffectFit
from eyehil.analysis.discrepancy.stats import Comparison, compare
from eyehil.emulator import effects as registry
from eyehil.emulator.effects import Applied
from eyehil.emulator.eye.model import EyeModel
from eyehil.parallel import worker_pool


@dataclass(frozen=True)
class Interaction:
    """D on the search eyes with the added effects alone and together (module docstring)."""

    D0: float
    alone: dict[str, float]
    together: float
    comparisons: dict[str, Comparison] = field(default_factory=dict)  # each alone, and "together"

    @property
    def interaction(self) -> float:
        return float(self.D0 - self.together - sum(self.D0 - d for d in self.alone.values()))


@dataclass(eq=False)
class DiscrepancyResult:
    """The rounds, the effects added, the final comparisons and the outcome (module docstring)."""

    measured: Measured
    rounds: list[Round]
    added: list[Applied]
    before: Comparison  # show eyes, the model without the added effects
    after: Comparison  # show eyes, with them
    final: Comparison  # search eyes, with them
    outcome: str
    reason: str
    named: list[Applied] = field(default_factory=list)  # in order of size ("explained" only)
    fits: list[EffectFit] = field(default_factory=list)  # the added effects' fits, in the order added
    interactions: Interaction | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    gof_p: float | None = None  # goodness of fit of the final model (search eyes), None if nothing added

    @property
    def shrink(self) -> float:
        """1 - D_after / D_before on the show eyes (0 when nothing was added)."""
        return 1.0 - self.after.D / self.before.D if self.before.D > 0 else 0.0

    @property
    def k_total(self) -> int:
        return sum(len(a.effect.fitted) for a in self.added)

    def summary(self) -> dict[str, Any]:
        """What summary.json holds: the named effects in order, the rivals of each added one (`Round.rivals`) and
        its twins (`Effect.twins`: effects no recording tells from it, fitted or not),
        their parameters (value, 1 sigma, 95 % half-width, edge flags), D before and after on the show eyes, the
        outcome and its reason."""
        by_name = {f.effect.name: f for f in self.fits}
        parameters = {}
        for a in self.added:
            f = by_name[a.effect.name]
            parameters[a.effect.name] = {p.name: {"value": f.values[p.name], "sigma": f.sigma.get(p.name),
                                                  "ci95": f.ci95.get(p.name), "unit": p.unit,
                                                  "at_edge": p.name in f.at_edge} for p in a.effect.fitted}
        return {"outcome": self.outcome, "reason": self.reason,
                "named_effects": [a.effect.name for a in self.named],
                "rivals": {r.added.effect.name: r.rivals for r in self.rounds
                           if r.added is not None and r.added.effect.name in by_name},
                "twins": {a.effect.name: list(a.effect.twins) for a in self.added if a.effect.twins},
                "partial_effects": [] if self.outcome == "explained" else [a.effect.name for a in self.added],
                "parameters": parameters,
                "gap_before": {"D": self.before.D, "significant": [g.condition for g in self.before.significant]},
                "gap_after": {"D": self.after.D, "significant": [g.condition for g in self.after.significant]},
                "gap_search_final": {"D": self.final.D, "gof_p": self.gof_p,
                                     "significant": [g.condition for g in self.final.significant]},
                "shrink": self.shrink,
                "interaction": None if self.interactions is None else {
                    "D0": self.interactions.D0, "alone": self.interactions.alone,
                    "together": self.interactions.together, "interaction": self.interactions.interaction}}


def run_discrepancy(measured: Measured, *, eyes: EyeModel, search_eyes: EyeModel | None = None,
                    effect_names: Sequence[str] | None = None, rounds: int = 2, alpha: float = 0.05,
                    seed: int = 0, workers: int = 1, progress: Progress | None = None,
                    memo: Memo | None = None) -> DiscrepancyResult:
    """The whole workflow (module docstring); `search_eyes` defaults to `eyes`; `workers` > 1 evaluates the
    points of each search stage in that many processes; `progress` hears of every stage; a `memo` keeps the
    evaluated points for later runs on the same model eyes (`eyehil.analysis.discrepancy.metrics.Memo`)."""
    progress = progress or Silent()
    with worker_pool(workers) if workers > 1 else nullcontext() as pool:  # Ctrl-C: the workers stop at once
        progress.stage("simulating and calibrating the search eyes", 1)
        search = initial = Evaluator(measured.experiment, search_eyes if search_eyes is not None else eyes,
                                     seed=seed, pool=pool, workers=workers, memo=memo)
        progress.advance(1)
        done, added, fits = [], [], []
        names = list(effect_names or registry.names())
        for i in range(rounds):
            free = partial(added_profile, initial, measured, list(added), progress) if added else None
            current = run_round(search, measured, names, alpha, progress, f"round {i + 1}", free,
                             sum(len(a.effect.fitted) for a in added))
            moved = restart(initial, measured, done, current, added, fits, alpha, progress) if added else None
            if moved is not None:
                done, current, added, fits, search = moved
                done.append(current)
                continue
            done.append(current)
            if current.added is None:
                break
            added.append(current.added.applied)
            fits.append(current.added)
            progress.stage(f"round {i + 1}: the model with {current.added.effect.name}", 1)
            search = search.with_base(added)
            progress.advance(1)
        backfitted = len(added) > 1
        if backfitted:
            added, fits, search = settle(initial, search, measured, added, fits, alpha, progress)
            for j in reversed(range(len(done))):  # the last round first: its fits are the most biased
                if done[j].added is not None:
                    done[j], added, fits, search = contend(initial, search, measured, done[j], j, added, fits,
                                                            alpha, progress)
            added, fits, search, done = drop_off(initial, search, added, fits, done)
        # the last round's own comparison is the final model's unless that round or the backfit changed the model
        final = find(search, measured, alpha) if backfitted or done[-1].added is not None else done[-1].before
        progress.stage(f"show: {len(eyes)} eyes without and with the added effects", 2)
        if search_eyes is None:
            show_before, show_after = initial, search
        else:
            show_before = Evaluator(measured.experiment, eyes, seed=seed, pool=pool, workers=workers, memo=memo)
            progress.advance(1)
            show_after = show_before.with_base(added) if added else show_before
        progress.advance(1)
        before, after = find(show_before, measured, alpha), find(show_after, measured, alpha)
        k_total = sum(len(a.effect.fitted) for a in added)
        gof = goodness_of_fit(search, measured, final, k_total) if added else None
        outcome, reason = decide(done, final, after, k_total, gof)
        if outcome == "none explains" and added:
            other = explain(initial, show_before, measured, done, added, fits, reason.split(": ", 1)[-1], alpha,
                             progress)
            if other is not None:
                done, added, fits, search = other.rounds, other.added, other.fits, other.search
                final, after, gof, k_total, reason = other.final, other.after, other.gof, other.k, other.reason
                outcome = "explained"
        interactions = None
        if len(added) > 1:
            progress.stage("interactions of the added effects", 1)
            points = [[a] for a in added] + [list(added)]
            comps = [compare(m, measured, initial.experiment.reference, alpha, tests=False)
                     for m in initial.evaluate(points)]
            labels = [a.effect.name for a in added] + ["together"]
            alone = {a.effect.name: c.D for a, c in zip(added, comps, strict=False)}
            interactions = Interaction(done[0].before.D, alone, comps[-1].D, dict(zip(labels, comps, strict=True)))
            progress.advance(1)
    named = []
    if outcome == "explained":
        size = {a.effect.name: (interactions.alone[a.effect.name] if interactions else final.D) for a in added}
        named = sorted(added, key=lambda a: size[a.effect.name])  # lowest D alone = explains most
    settings = {"experiment": measured.experiment, "eyes": len(show_before.eyes), "search_eyes": len(initial.eyes),
                "rounds": rounds, "alpha": alpha, "alpha_gof": ALPHA_GOF, "seed": seed,
                "evaluations": sum(len(f.points) for r in done for f in r.fits)}
    return DiscrepancyResult(measured, done, added, before, after, final, outcome, reason, named, fits,
                             interactions, settings, gof if added else None)


def hidden_measured(hidden: Sequence[Applied], *, eyes: EyeModel, experiment: str = "guestrin2006",
                    conditions: Sequence[str] | None = None, seed: int = 1) -> Measured:
    """Per-subject "measured" conditions of `eyes` simulated with `hidden` effects (noise seed `seed`)."""
    evaluator = Evaluator(experiment, eyes, base=hidden, seed=seed)
    names = tuple(conditions or evaluator.experiment.diagnostic_conditions(evaluator.host))
    values = np.array([evaluator.base_metrics[c] for c in names])
    keep = np.all(np.isfinite(values), axis=0)
    labels = [a.label() for a in hidden] or ["none"]
    if keep.sum() < 2:
        raise ValueError(f"with {', '.join(labels)} only {keep.sum()} of {keep.size} eyes give features in every "
                         "condition (the workflow needs 2): a value far outside the effect's plausible range?")
    subjects = tuple(f"eye{i + 1}" for i in np.flatnonzero(keep))
    data = {c: MeasuredCondition.of(v[keep]) for c, v in zip(names, values, strict=True)}
    return Measured(experiment, data, subjects, f"simulated: {len(subjects)} eyes, hidden {', '.join(labels)}",
                    {"hidden": labels})
