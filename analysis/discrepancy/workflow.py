"""The discrepancy workflow: find where simulation and measured data disagree, name the missing effect(s),
add them to the model, and show the gap shrink, or say that no known effect explains it.

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
   earlier rounds' effects free near their fits (`_profile`, `eyehil.analysis.discrepancy.profile`: D minimised
   over a linear shift of their parameters), for their fits are biased by the gap still open when they were made.
3. add: the top-ranked effect with no fitted parameter at the edge of its plausible range joins the model at
   its fitted values if it lowers D by more than the chi-square(k) point at level 1 - `ALPHA_ADD` / n (after the
   misfit scale factor; `add_level`: Bonferroni over the n candidates fitted in the round, for the best of n is
   chosen after seeing the data; `EffectFit.passes`). A fit at an edge is evidence against its effect: it is
   reported and never added, and the next candidate is considered (the search refined it for that case). If
   nothing passes, nothing is added and the round says why.
   Steps 1-3 repeat for up to `rounds` rounds (a second effect is fitted with the first in the model).
   A later round whose best fit ends at an edge, or where nothing passes though a gap is left, is fitted again
   from other starts of the earlier effects: their screens' other basins, or their rounds' close contenders in
   their place (`_restart`: the earlier fits' bias can hold the round's effect at an edge or make it useless).
   With two or more effects added, each is refitted with the others in the model (`_backfit`), then all are
   moved together along their linear model while D falls (`_polish`: one effect at a time crawls along a valley
   where two trade off), and refitted again there (`_settle`); and so are every
   round's close contenders, the last round's first (`_contend`): up to `CONTENDERS` refined fits that lower D and
   score within `CONTEND` of the added one (after the added fit's misfit scale s^2), each backfitted in place of
   the effect its round added. The first effect was fitted
   while the second's gap was still open, so the round ranks the second's candidates against a biased first
   (a pupil decentration behind a corneal one, 93 against 76, that tie at 64 and 63 once the lens distortion
   fitted before them is refitted); the backfitted model of lowest D + 2k is kept, and the others within
   `RIVAL_SCORE` of it are its rivals.
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
  verdict, each round's close contenders, screened ones too (up to `ALTERNATIVES`), are tried in place of the
  effect it added, the model settled (`_explain`): a mimic can score best on the search eyes and still leave a
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

import itertools
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any, Protocol

import numpy as np
import scipy.stats as sps

from eyehil.analysis.discrepancy.data import Measured, MeasuredCondition
from eyehil.analysis.discrepancy.metrics import Evaluator, Memo
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
from eyehil.emulator.eye.model import EyeModel
from eyehil.parallel import worker_pool

ALPHA_GOF = 0.01
ALPHA_ADD = 0.05  # family-wise level of a round's addition, over its candidates (`add_level`)
RIVAL_SCORE = 2.0  # D + 2k within this of the added effect's: a rival the data cannot tell from it (`Round.rivals`)
CONTEND = 30.0  # D + 2k within this (/ s^2) of the effect its round added: backfitted in its place (`_contend`)
CONTENDERS = 2  # at most this many contenders backfitted
ALTERNATIVES = 3  # contenders a round tries in place of its effect before "none explains" (`_explain`)
POLISH, POLISH_GAIN = 4, 0.5  # joint moves of the added effects at most, and the least gain of D (`_polish`)
BASINS = 2  # other basins of each earlier effect an edge fit of a later round is backfitted from (`_restart`)
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
OUTCOMES = ("no gap", "explained", "none explains")


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
    backfitted: dict[str, float] | None = None  # D + 2k of the whole model backfitted with each (`_contend`)
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
            free = partial(_profile, initial, measured, list(added), progress) if added else None
            current = _round(search, measured, names, alpha, progress, f"round {i + 1}", free,
                             sum(len(a.effect.fitted) for a in added))
            moved = _restart(initial, measured, done, current, added, fits, alpha, progress) if added else None
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
            added, fits, search = _settle(initial, search, measured, added, fits, alpha, progress)
            for j in reversed(range(len(done))):  # the last round first: its fits are the most biased
                if done[j].added is not None:
                    done[j], added, fits, search = _contend(initial, search, measured, done[j], j, added, fits,
                                                            alpha, progress)
            added, fits, search, done = _drop_off(initial, search, added, fits, done)
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
        gof = _gof(search, measured, final, k_total) if added else None
        outcome, reason = decide(done, final, after, k_total, gof)
        if outcome == "none explains" and added:
            other = _explain(initial, show_before, measured, done, added, fits, reason.split(": ", 1)[-1], alpha,
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


def decide(rounds: list[Round], final: Comparison, show_after: Comparison, k_total: int,
           gof: float | None = None) -> tuple[str, str]:
    """The outcome and its reason (module docstring); `gof` the goodness-of-fit p of the final model
    (default the chi-square reading of D)."""
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


def _gof(model: Evaluator, measured: Measured, comparison: Comparison, k: int) -> float:
    """The goodness-of-fit p of `model`'s D (`comparison`, k parameters fitted): the permutation test where every
    measured condition has per-subject values (`permutation_gof`), else P(chi-square(n_terms - k) >= D)."""
    p = permutation_gof(model.base_metrics, measured, model.experiment.reference, comparison.D)
    return comparison.gof_p(k) if p is None else p


def _profile(initial: Evaluator, measured: Measured, added: list[Applied], progress: Progress) -> Profile:
    """The linear model of the added effects' parameters near their fits (`eyehil.analysis.discrepancy.profile`)."""
    points, spans, lo, hi = probes(added)
    progress.stage("the added effects' slopes", len(points))
    probed = initial.evaluate(points, progress.advance)
    return Profile.of(probed, spans, lo, hi,
                      lambda metrics: gap_terms(metrics, measured, initial.experiment.reference))


def _round(search: Evaluator, measured: Measured, effect_names, alpha, progress, label: str,
           free: Callable[[], Profile] | None = None, k: int = 0) -> Round:
    """Steps 1-3 once; `free` makes the profile over the earlier rounds' effects, if any (`_profile`), when the
    round has a gap to fit; `k` the parameters fitted so far (the chi-square reading of `Round.diffuse_p`)."""
    before = find(search, measured, alpha)
    diffuse = None
    if not before.significant:
        diffuse = _gof(search, measured, before, k)
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


def _restart(initial: Evaluator, measured: Measured, done: list[Round], current: Round, added: list[Applied],
             fits: list[EffectFit], alpha: float, progress: Progress
             ) -> tuple[list[Round], Round, list[Applied], list[EffectFit], Evaluator] | None:
    """A later round fitted beside earlier effects fitted while its gap was still open; two ways their bias can
    stop it, each met by fitting the round's best candidate again from other starts of the earlier effects:

    - its best fit ends at an edge of its range, ranked above the round's addition (if any): the earlier effects
      may hold it there. A screen tilt fitted in the wrong basin (its sign) beside a hidden camera bump pushes
      the bump's fit to its pitch's end, and the profile lets the tilt move by a quarter of its range only.
      Starts: the earlier effects as fitted, with the edge fit; and each of their screens' other basins
      (`EffectFit.basins`, up to `BASINS` each);
    - nothing passes though a gap is left and its best fit not at an edge lowers D (at 95 %, before the
      round's Bonferroni): an earlier round may have added a mimic of its effect, which the new one cannot
      complement (a glint occlusion for a corneal asphericity beside a tangential distortion). Starts: each
      earlier round's close contenders (`_close`) in place of the effect that round added.

    From each start the candidate is fitted (where it is not the edge fit itself) and the model settled
    (`_settle`); the settled model of least D with no parameter at an edge is kept if the candidate passes the
    round's level against the model of the earlier effects as they were and the model's D + 2k is below the
    round's (its addition's, if any). Returns the rounds before (a contender replaced in its round) and this
    round, the effects, their fits and the model's evaluator; or None (all as they were)."""
    ranked = itertools.takewhile(lambda f: f is not current.added, current.fits)
    edged = next((f for f in ranked if f.at_edge and not f.screened and f.lowers(current.level)), None)
    present = {a.effect.name for a in added}
    if edged is not None:
        chosen = edged
        starts = [(None, list(fits), edged)] + [(None, [*fits[:j], basin, *fits[j + 1:]], None)
                                                for j, f in enumerate(fits) for basin in f.basins()[:BASINS]]
    elif current.added is None and current.gap:
        chosen = next((f for f in current.fits if not f.screened and not f.at_edge), None)
        if chosen is None or not chosen.lowers():
            return None
        present.add(chosen.effect.name)
        starts = [(j, [*fits[:j], c, *fits[j + 1:]], None) for j, r in enumerate(done) for c in _close(r, present)]
    else:
        return None
    reference = initial.experiment.reference
    progress.stage(f"round {len(done) + 1}: {chosen.effect.name} from {len(starts)} starts of the earlier effects",
                   sum(max_evaluations(chosen.effect) for _, _, new in starts if new is None))
    best = None
    for j, start, new in starts:
        if new is None:  # the candidate refitted beside this start
            model = initial.with_base([f.applied for f in start])
            before = compare(model.base_metrics, measured, reference, alpha, tests=False)
            [new] = name_effects(model, measured, before, [chosen.effect.name], alpha, progress)
        trial_fits = [*start, new]
        trial = [f.applied for f in trial_fits]
        trial, trial_fits, model = _settle(initial, initial.with_base(trial), measured, trial, trial_fits, alpha,
                                           progress)
        if any(f.at_edge for f in trial_fits):
            continue
        D = compare(model.base_metrics, measured, reference, alpha, tests=False).D
        if best is None or best[0] > D:
            best = D, j, trial, trial_fits, model
    if best is None:
        return None
    D, j, trial, trial_fits, model = best
    fit = replace(trial_fits[-1], D=D, D0=current.before.D)  # the drop from the earlier effects as they were
    k_before = sum(f.k for f in fits)
    if current.added is not None:
        k_before, D_before = k_before + current.added.k, current.added.D
    else:
        D_before = current.before.D
    if not fit.passes(current.level) or D + 2 * sum(f.k for f in trial_fits) >= D_before + 2 * k_before:
        return None
    rounds = list(done)
    if edged is not None:
        how = (f"{edged.applied.label()} ends at the edge of its plausible range ({', '.join(edged.at_edge)}); "
               "backfitted with the earlier effects it leaves the edge")
    else:
        how = (f"{chosen.applied.label()} does not pass beside {fits[j].applied.label()}; with "
               f"{trial_fits[j].applied.label()} in its place (round {j + 1}'s contender) it does")
        rounds[j] = replace(done[j], added=trial_fits[j], verdict=(
            f"{done[j].verdict}; {trial_fits[j].effect.name} fits better in its place beside round "
            f"{len(done) + 1}'s {fit.effect.name}: {trial_fits[j].applied.label()}"))
    verdict = f"{how}: added {fit.applied.label()}: D {fit.D0:.1f} -> {fit.D:.1f}"
    return rounds, replace(current, added=fit, verdict=verdict), trial, [*trial_fits[:-1], fit], model


def _close(done: Round, present: set[str], count: int = CONTENDERS, screened: bool = False,
           own: EffectFit | None = None) -> list[EffectFit]:
    """A round's close contenders: up to `count` other fits, refined ones only unless `screened`, that pass at its
    level and score within `CONTEND` of `own` (default its added effect; after its misfit scale s^2), of effects
    not in the model."""
    assert done.added is not None
    own = own or done.added
    return [f for f in done.fits if f is not own and (screened or not f.screened) and f.passes(done.level)
            and (f.score - own.score) / own.scale**2 <= CONTEND
            and f.effect.name not in present][:count]


def _explain(initial: Evaluator, show: Evaluator, measured: Measured, done: list[Round], added: list[Applied],
             fits: list[EffectFit], failed: str, alpha: float, progress: Progress) -> _Model | None:
    """Before "none explains" (`failed` its reason): each round's close contenders, screened ones too (up to
    `ALTERNATIVES`), in place of the effect the round added, the model settled (`_settle`). A mimic can score
    better on the search eyes and still leave a gap on the show eyes (a pupil shift for a head roll beside a
    corneal astigmatism, D + 2k 23.9 against 35.5, the shift's model leaving the show eyes' spread at H2): the
    model the outcome's criterion (`decide`) finds explains the data is kept, of least D + 2k if more than one
    do, with no parameter at an edge and none at its neutral value. `show` is the show eyes' evaluator without
    effects. Returns that model (`_Model`), or None."""
    names = [a.effect.name for a in added]
    present = set(names)
    tries = [(j, names.index(r.added.effect.name), f) for j, r in enumerate(done)
             if r.added is not None and r.added.effect.name in present
             for f in _close(r, present, ALTERNATIVES, screened=True, own=_own(r))]
    if not tries:
        return None
    progress.stage(f"before 'none explains': {len(tries)} contenders in place of the added effects",
                   len(tries) * sum(max_evaluations(a.effect) for a in added))
    best = None
    for j, i, f in tries:
        trial, trial_fits = [*added[:i], f.applied, *added[i + 1:]], [*fits[:i], f, *fits[i + 1:]]
        trial, trial_fits, model = _settle(initial, initial.with_base(trial), measured, trial, trial_fits, alpha,
                                           progress)
        if any(t.at_edge or t.off for t in trial_fits):
            continue
        final = find(model, measured, alpha)
        k = sum(t.k for t in trial_fits)
        score = final.D + 2 * k
        if best is not None and score >= best.final.D + 2 * best.k:
            continue
        rounds = list(done)
        scores = None if done[j].backfitted is None else {**done[j].backfitted, f.effect.name: score}
        rounds[j] = replace(done[j], added=trial_fits[i], backfitted=scores, verdict=(
            f"{done[j].verdict}; the model with {names[i]} leaves a gap ({failed}); with "
            f"{trial_fits[i].applied.label()} in its place it explains the data"))
        after = find(show.with_base(trial), measured, alpha)
        gof = _gof(model, measured, final, k)
        outcome, reason = decide(rounds, final, after, k, gof)
        if outcome == "explained":
            best = _Model(rounds, trial, trial_fits, model, final, after, gof, reason)
    return best


def _own(done: Round) -> EffectFit:
    """The fit the round made of the effect it added (its `added` may be the backfitted one, scored with the later
    effects in the model)."""
    assert done.added is not None
    return next((f for f in done.fits if f.effect.name == done.added.effect.name), done.added)


@dataclass(frozen=True, eq=False)
class _Model:
    """A model `_explain` keeps: the rounds (one with a contender in place of its added effect), the effects and
    their fits, the model's evaluator and comparisons (search eyes, show eyes), its goodness of fit and the
    outcome's reason."""

    rounds: list[Round]
    added: list[Applied]
    fits: list[EffectFit]
    search: Evaluator
    final: Comparison
    after: Comparison
    gof: float
    reason: str

    @property
    def k(self) -> int:
        """The model's fitted parameters."""
        return sum(f.k for f in self.fits)


def _drop_off(initial: Evaluator, search: Evaluator, added: list[Applied], fits: list[EffectFit], done: list[Round]
              ) -> tuple[list[Applied], list[EffectFit], Evaluator, list[Round]]:
    """The added effects that, refitted beside the others, do nothing (`EffectFit.off`: a feature noise polished
    to 0 px beside the glint occlusion it stood in for) leave the model, and their rounds say so."""
    off = {f.effect.name for f in fits if f.off}
    if not off:
        return added, fits, search, done
    rounds = [replace(r, verdict=f"{r.verdict}; refitted beside the later effects it does nothing "
                                 f"({r.added.effect.name} at its neutral value): dropped")
              if r.added is not None and r.added.effect.name in off else r for r in done]
    kept = [(a, f) for a, f in zip(added, fits, strict=True) if f.effect.name not in off]
    added, fits = [a for a, _ in kept], [f for _, f in kept]
    return added, fits, initial.with_base(added), rounds


def _settle(initial: Evaluator, search: Evaluator, measured: Measured, added: list[Applied],
            fits: list[EffectFit], alpha: float, progress: Progress
            ) -> tuple[list[Applied], list[EffectFit], Evaluator]:
    """`_backfit`, then `_polish`; if the polish moved the effects, `_backfit` again there (each fit's uncertainty
    is its own refit's), unless that leaves more parameters at an edge of their range. Same arguments and returns
    as `_backfit`."""
    added, fits, search = _backfit(initial, search, measured, added, fits, alpha, progress)
    moved, D = _polish(initial, measured, added, search, alpha, progress)
    if moved is not added:
        polished = [replace(f, values=dict(a.values), D=D) for f, a in zip(fits, moved, strict=True)]
        after = _backfit(initial, initial.with_base(moved), measured, moved, polished, alpha, progress)
        if sum(len(f.at_edge) for f in after[1]) <= sum(len(f.at_edge) for f in fits):
            added, fits, search = after
    return added, _fill_sigma(initial, measured, added, fits, search, alpha, progress), search


def _fill_sigma(initial: Evaluator, measured: Measured, added: list[Applied], fits: list[EffectFit],
                model: Evaluator, alpha: float, progress: Progress) -> list[EffectFit]:
    """The fits with an unknown uncertainty (NaN: a point a polish or a basin's node gave, where the search's own
    refit ends elsewhere, at an edge: a glint occlusion's bias) get the linear model's at the model's point
    (`Profile.sigma`, times the model's misfit scale s)."""
    if not any(np.isnan(v) for f in fits for v in f.sigma.values()):
        return fits
    sigma = _profile(initial, measured, added, progress).sigma(model.base_metrics)
    D = compare(model.base_metrics, measured, initial.experiment.reference, alpha, tests=False).D
    dof = fits[0].n_conditions - sum(f.k for f in fits)
    scale = float(np.sqrt(max(1.0, D / dof))) if dof > 0 else 1.0
    out, at = [], 0
    for f in fits:
        own = dict(zip((p.name for p in f.effect.fitted), scale * sigma[at:at + f.k], strict=True))
        out.append(replace(f, sigma={n: (float(own[n]) if np.isnan(v) else v) for n, v in f.sigma.items()}))
        at += f.k
    return out


def _polish(initial: Evaluator, measured: Measured, added: list[Applied], model: Evaluator, alpha: float,
            progress: Progress) -> tuple[list[Applied], float]:
    """All added effects' parameters moved together, up to `POLISH` times, by the least-D shift of their linear
    model (`_profile`: two simulations per parameter, each shift within a quarter of the range), while D falls:
    a backfit refits one effect at a time, which crawls along a valley where two effects trade off (a screen tilt
    and a camera bump). Returns the effects (the list `added` itself if none moved) and their D."""
    reference = initial.experiment.reference
    D = compare(model.base_metrics, measured, reference, alpha, tests=False).D
    for _ in range(POLISH):
        profile = _profile(initial, measured, added, progress)
        delta, moved, at = profile.best_shift(model.base_metrics)[0], [], 0
        for a in added:
            k = len(a.effect.fitted)
            values = {p.name: float(a.values[p.name] + d) for p, d in zip(a.effect.fitted, delta[at:at + k],
                                                                           strict=True)}
            moved.append(Applied(a.effect, {**a.values, **values}))
            at += k
        trial = initial.with_base(moved)
        D_trial = compare(trial.base_metrics, measured, reference, alpha, tests=False).D
        if not D_trial < D - POLISH_GAIN:
            break
        added, model, D = moved, trial, D_trial
    return added, D


def _backfit(initial: Evaluator, search: Evaluator, measured: Measured, added: list[Applied],
             fits: list[EffectFit], alpha: float, progress: Progress
             ) -> tuple[list[Applied], list[EffectFit], Evaluator]:
    """Refit each added effect with the others in the model at their current values (one sweep, in the order
    added); `search` is the evaluator with all of `added` in its base. The first effect was fitted while the
    second's gap was still unexplained and took up part of it; refitted with the second in the model it gives
    that part back. A refit replaces the effect's values only where it lowers D with all added effects and ends
    inside the plausible range. Returns the effects, their fits and the evaluator of the final model."""
    added, fits = list(added), list(fits)
    reference = initial.experiment.reference
    current = compare(search.base_metrics, measured, reference, alpha, tests=False).D
    progress.stage("backfitting the added effects", sum(max_evaluations(a.effect) for a in added))
    changed = False
    for j, applied in enumerate(added):
        others = initial.with_base(added[:j] + added[j + 1:])
        before = compare(others.base_metrics, measured, reference, alpha, tests=False)
        [fit] = name_effects(others, measured, before, [applied.effect.name], alpha, progress)
        if current > fit.D and not fit.at_edge:
            added[j], fits[j], current, changed = fit.applied, fit, fit.D, True
        elif any(np.isnan(v) for v in fits[j].sigma.values()):  # a basin's node or a polished point: no sigma of
            fits[j] = replace(fits[j], sigma=fit.sigma)  # its own, the refit's at the others as they are
    return added, fits, initial.with_base(added) if changed else search


def _contend(initial: Evaluator, search: Evaluator, measured: Measured, last: Round, j: int, added: list[Applied],
             fits: list[EffectFit], alpha: float, progress: Progress
             ) -> tuple[Round, list[Applied], list[EffectFit], Evaluator]:
    """A round's contenders (module docstring, step 3), each put in place of the effect the round added (the
    `j`-th) and the model backfitted; returns the round with the scores of the backfitted models
    (`Round.backfitted`) and its added effect the best of them, and the model of that one."""
    assert last.added is not None
    close = _close(last, {a.effect.name for a in added})
    if not close:
        return last, added, fits, search
    reference = initial.experiment.reference

    def score(model: Evaluator, chosen: list[Applied]) -> float:
        D = compare(model.base_metrics, measured, reference, alpha, tests=False).D
        return D + 2 * sum(len(a.effect.fitted) for a in chosen)

    own = added[j].effect.name
    models = {own: (score(search, added), added, fits, search)}
    for f in close:
        trial_added, trial_fits = [*added[:j], f.applied, *added[j + 1:]], [*fits[:j], f, *fits[j + 1:]]
        model = initial.with_base(trial_added)
        trial_added, trial_fits, model = _settle(initial, model, measured, trial_added, trial_fits, alpha, progress)
        models[f.effect.name] = (score(model, trial_added), trial_added, trial_fits, model)
    name = min(models, key=lambda n: models[n][0])
    _, added, fits, search = models[name]
    verdict = last.verdict if name == own else (
        f"{last.verdict}; backfitted, {name} fits better in its place: {fits[j].applied.label()}")
    return (replace(last, added=fits[j], verdict=verdict, backfitted={n: m[0] for n, m in models.items()}),
            added, fits, search)


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
