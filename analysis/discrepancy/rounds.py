"""One round of the discrepancy workflow on the search eyes (`eyehil.analysis.discrepancy.workflow`, steps 1-3),
and the criterion of its outcome (`decide`).

- find (`find`): the current model's gaps; where no condition is significant, D itself is tested
  (`Round.diffuse_p`, `goodness_of_fit`).
- name (`name_effects`): every candidate effect fitted to minimise D and ranked by D + 2k; from round 2 on, scored
  with the earlier rounds' effects free near their fits (`added_profile`).
- add (`choose`): the best fit not at an edge of its plausible range, if it passes at the round's `add_level`.

`run_round` runs the three once; `Round` keeps what it found, fitted and added, and the rivals the data cannot tell
from its addition (`Round.rivals`).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import scipy.stats as sps

from eyehil.analysis.discrepancy.data import Measured
from eyehil.analysis.discrepancy.metrics import Evaluator
from eyehil.analysis.discrepancy.profile import Profile, probes
from eyehil.analysis.discrepancy.search import TOP, EffectFit, max_evaluations, search_effects
from eyehil.analysis.discrepancy.stats import (
    Comparison,
    compare,
    gap_measure,
    gap_terms,
    permutation_gof,
    resampled_gap_measure,
    term_covariance,
)
from eyehil.emulator import effects as registry
from eyehil.emulator.effects import Applied, Effect

ALPHA_GOF = 0.01
ALPHA_ADD = 0.05  # family-wise level of a round's addition, over its candidates (`add_level`)
RIVAL_SCORE = 2.0  # D + 2k within this of the added effect's: a rival the data cannot tell from it (`Round.rivals`)
CHUNK = 12  # points per evaluation call (each a batched calibration)


def add_level(n_candidates: int) -> float:
    """The chi-square level the best of a round's `n_candidates` fits must pass to be added: 1 - ALPHA_ADD / n
    (Bonferroni). The best is picked after seeing the data, so testing it at 95 % alone adds a spurious
    effect in up to n x 5 % of rounds that have nothing left to explain."""
    return 1.0 - ALPHA_ADD / max(1, n_candidates)


def _evaluations(chosen: Sequence[Effect]) -> int:
    """Evaluations of a round at most: every effect's screen, the `TOP` largest refinements."""
    refine = sorted((max_evaluations(e) - max_evaluations(e, refined=False) for e in chosen), reverse=True)
    return sum(max_evaluations(e, refined=False) for e in chosen) + sum(refine[:TOP])


class Progress(Protocol):
    """Where the workflow reports what it does: a stage with its number of steps, then steps done."""

    def stage(self, label: str, total: int) -> None: ...

    def advance(self, n: int) -> None: ...


class Silent:
    """A `Progress` that reports nothing."""

    def stage(self, label: str, total: int) -> None:
        pass

    def advance(self, n: int) -> None:
        pass


@dataclass(frozen=True, eq=False)
class Round:
    """One find-name-add round on the search eyes."""

    before: Comparison
    fits: list[EffectFit]  # ranked, best first
    added: EffectFit | None
    verdict: str
    level: float = 0.95  # the addition's chi-square level (`add_level`)
    backfitted: dict[str, float] | None = None  # D + 2k of the whole model backfitted with each (`refit.contend`)
    diffuse_p: float | None = None  # where no condition is significant: the goodness-of-fit p of D (step 1)

    @property
    def gap(self) -> bool:
        """Whether step 1 found a gap: a significant condition, or D beyond chance (`diffuse_p` below alpha)."""
        return bool(self.before.significant) or (self.diffuse_p is not None and self.diffuse_p < self.before.alpha)

    @property
    def rivals(self) -> list[str]:
        """The other candidates the data cannot tell from the added effect: each lowers D significantly too
        (`EffectFit.lowers` at the round's `level`) and its D + 2k is within `RIVAL_SCORE` of the added one's;
        after a backfit of contenders, D + 2k of the backfitted models. Those only screened carry the surrogate's
        D, which a refinement would lower further, so the list errs on the short side."""
        if self.added is None:
            return []
        if self.backfitted:
            best = self.backfitted[self.added.effect.name]
            return [n for n, v in self.backfitted.items()
                    if n != self.added.effect.name and abs(v - best) <= RIVAL_SCORE]
        return [f.effect.name for f in self.fits
                if f.effect.name != self.added.effect.name and f.lowers(self.level)
                and f.score - self.added.score <= RIVAL_SCORE]


def find(evaluator: Evaluator, measured: Measured, alpha: float = 0.05) -> Comparison:
    """Step 1: the current model's gaps (with the permutation tests)."""
    return compare(evaluator.base_metrics, measured, evaluator.experiment.reference, alpha)


def candidates(evaluator: Evaluator, names: Sequence[str] | None = None) -> list[Effect]:
    """Catalogue effects that can act in this experiment and are not in the model yet."""
    present = {a.effect.name for a in evaluator.base}
    chosen = [registry.get(n) for n in (names or registry.names())]
    one_session = len(evaluator.host.head_positions) < 2
    return [e for e in chosen if e.name not in present and not (e.validation_only and one_session)]


def name_effects(evaluator: Evaluator, measured: Measured, before: Comparison, effect_names=None,
                 alpha: float = 0.05, progress: Progress | None = None,
                 profile: Profile | None = None) -> list[EffectFit]:
    """Step 2: every candidate effect fitted (batched together), ranked by D + 2k (best first); with a `profile`,
    every point is scored with the earlier rounds' effects free (`eyehil.analysis.discrepancy.profile`)."""
    progress = progress or Silent()
    free = profile if profile is not None else (lambda metrics: metrics)
    one = profile.one if profile is not None else (lambda metrics: metrics)

    def score(metrics) -> np.ndarray:
        D = gap_measure(free(metrics), measured, evaluator.experiment.reference)
        if np.isnan(D).any():
            raise ValueError("a simulation has fewer than 2 eyes with a finite value in some condition")
        return D

    def evaluate(batch: list[Applied]) -> list:
        out = []
        for i in range(0, len(batch), CHUNK):  # chunks, so that progress is heard every few seconds
            out += evaluator.evaluate([[a] for a in batch[i:i + CHUNK]])
            progress.advance(len(batch[i:i + CHUNK]))
        return out

    def terms(metrics) -> np.ndarray:
        return gap_terms(free(metrics), measured, evaluator.experiment.reference)

    def covariance(metrics) -> np.ndarray:
        return term_covariance(one(metrics), measured, evaluator.experiment.reference)

    def resample(metrics) -> np.ndarray:
        return resampled_gap_measure(free(metrics), measured, evaluator.experiment.reference)

    fits = search_effects(candidates(evaluator, effect_names), evaluate, score, before.D, before.n_terms,
                          sandwich=(terms, covariance, resample))
    return sorted(fits, key=lambda f: (f.screened, f.score))


def run_round(search: Evaluator, measured: Measured, effect_names, alpha, progress, label: str,
              free: Callable[[], Profile] | None = None, k: int = 0) -> Round:
    """Steps 1-3 once; `free` makes the profile over the earlier rounds' effects, if any (`added_profile`), when the
    round has a gap to fit; `k` the parameters fitted so far (the chi-square reading of `Round.diffuse_p`)."""
    before = find(search, measured, alpha)
    diffuse = None
    if not before.significant:
        diffuse = goodness_of_fit(search, measured, before, k)
        if not diffuse < alpha:
            return Round(before, [], None, f"no significant gap (nor D as a whole: goodness-of-fit p = {diffuse:.2g})"
                                           ": nothing to add", diffuse_p=diffuse)
    profile = free() if free is not None else None
    chosen = candidates(search, effect_names)
    progress.stage(f"{label}: fitting {len(chosen)} effects", _evaluations(chosen))
    fits = name_effects(search, measured, before, effect_names, alpha, progress, profile) \
        if effect_names is None or len(effect_names) else []
    chosen_round = choose(before, fits)
    if diffuse is None:
        return chosen_round
    return replace(chosen_round, diffuse_p=diffuse, verdict=(
        f"no condition is significant, but D = {before.D:.1f} is beyond chance (goodness-of-fit p = {diffuse:.2g}): "
        f"{chosen_round.verdict}"))


def choose(before: Comparison, fits: list[EffectFit]) -> Round:
    """Step 3 on a round's ranked fits: the best fit not at an edge of its range is added if it passes at the
    round's `add_level` (a fit at an edge is evidence against its effect: it is reported, not added, and does not
    stand in the way of the next)."""
    level = add_level(len(fits))
    free = next((f for f in fits if not f.at_edge), None)
    best = free if free is not None and free.passes(level) else None
    return Round(before, fits, best, _verdict(best, free, fits, level), level)


def _verdict(best: EffectFit | None, top: EffectFit | None, fits: list[EffectFit], level: float) -> str:
    """Why the round added `best` (or nothing); `top` the best fit not at an edge, the ones before it at edges."""
    if not fits:
        return "no candidate effect left"
    edged = [f for f in itertools.takewhile(lambda f: f is not top, fits) if f.lowers(level)]
    edges = "; ".join(f"{f.applied.label()} ends at the edge of its plausible range ({', '.join(f.at_edge)}): "
                      "not added" for f in edged)
    if best is not None:
        return f"added {best.applied.label()}: D {best.D0:.1f} -> {best.D:.1f}" + (f" ({edges})" if edges else "")
    if top is None:  # every candidate ends at an edge
        return f"the best, {edges}" if edges else "every candidate ends at an edge of its plausible range"
    return ((f"{edges}; " if edges else "") + f"the best{' not at an edge' if edged else ''}, {top.applied.label()}, "
            f"lowers D by {top.reduction:.2f}, {top.reduction / top.scale**2:.2f} after the misfit scale (needs > "
            f"{sps.chi2.ppf(level, top.k):.2f}, the chi-square({top.k}) point at {100 * level:.2f} %, Bonferroni "
            f"over {len(fits)} candidates)")


def decide(rounds: list[Round], final: Comparison, show_after: Comparison, k_total: int,
           gof: float | None = None) -> tuple[str, str]:
    """The outcome and its reason (the criterion of `eyehil.analysis.discrepancy.workflow`'s docstring); `gof`
    the goodness-of-fit p of the final model (default the chi-square reading of D)."""
    first = rounds[0]
    if not first.gap and first.added is None:
        return "no gap", "no significant gap between the model and the data: nothing added"
    if not any(r.added for r in rounds):
        return "none explains", f"none of the known effects explains the gap: {first.verdict}"
    problems = []
    if final.significant:
        problems.append("significant gaps left on the search eyes: " + ", ".join(g.compared for g in final.significant))
    if show_after.significant:
        problems.append("significant gaps left on the show eyes: "
                        + ", ".join(f"{g.compared} ({g.kinds(show_after.alpha)})" for g in show_after.significant))
    gof = final.gof_p(k_total) if gof is None else gof
    if gof < ALPHA_GOF:
        problems.append(f"the final model does not fit: D = {final.D:.1f} over {final.n_terms} terms, "
                        f"{k_total} fitted, goodness-of-fit p = {gof:.2g} < {ALPHA_GOF}")
    if problems:
        return "none explains", "none of the known effects explains the gap: " + "; ".join(problems)
    return "explained", (f"no significant gap left (search and show eyes) and the model fits: D = {final.D:.1f} "
                         f"over {final.n_terms} terms, goodness-of-fit p = {gof:.2g}")


def goodness_of_fit(model: Evaluator, measured: Measured, comparison: Comparison, k: int) -> float:
    """The goodness-of-fit p of `model`'s D (`comparison`, k parameters fitted): the permutation test where every
    measured condition has per-subject values (`permutation_gof`), else P(chi-square(n_terms - k) >= D)."""
    p = permutation_gof(model.base_metrics, measured, model.experiment.reference, comparison.D)
    return comparison.gof_p(k) if p is None else p


def added_profile(initial: Evaluator, measured: Measured, added: list[Applied], progress: Progress) -> Profile:
    """The linear model of the added effects' parameters near their fits (`eyehil.analysis.discrepancy.profile`)."""
    points, spans, lo, hi = probes(added)
    progress.stage("the added effects' slopes", len(points))
    probed = initial.evaluate(points, progress.advance)
    return Profile.of(probed, spans, lo, hi,
                      lambda metrics: gap_terms(metrics, measured, initial.experiment.reference))
