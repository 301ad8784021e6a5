"""The added effects refitted together, and other effects tried in their places
(`eyehil.analysis.discrepancy.workflow`, step 3): the first effect was fitted while the second's gap was still
open, so its fit is biased by the gap a later round takes up.

- `settle`: each added effect refitted beside the others (`_backfit`), all moved together along their linear model
  while D falls (`_polish`), and refitted there.
- `restart`: a later round whose best fit ends at an edge, or where nothing passes though a gap is left, fitted
  again from other starts of the earlier effects (their screens' other basins, their rounds' close contenders).
- `contend`: a round's close contenders backfitted in place of the effect it added; the model of least D + 2k is
  kept.
- `drop_off`: an added effect that, refitted beside the later ones, does nothing leaves the model.
- `explain`: before the verdict "none explains", each round's contenders in place of its effect, the model kept if
  it meets the criterion of "explained" (`eyehil.analysis.discrepancy.rounds.decide`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from eyehil.analysis.discrepancy.data import Measured
from eyehil.analysis.discrepancy.metrics import Evaluator
from eyehil.analysis.discrepancy.rounds import (
    Progress,
    Round,
    added_profile,
    decide,
    find,
    goodness_of_fit,
    name_effects,
)
from eyehil.analysis.discrepancy.search import EffectFit, max_evaluations
from eyehil.analysis.discrepancy.stats import Comparison, compare
from eyehil.emulator.effects import Applied

CONTEND = 30.0  # D + 2k within this (/ s^2) of the effect its round added: backfitted in its place (`contend`)
CONTENDERS = 2  # at most this many contenders backfitted
ALTERNATIVES = 3  # contenders a round tries in place of its effect before "none explains" (`explain`)
POLISH, POLISH_GAIN = 4, 0.5  # joint moves of the added effects at most, and the least gain of D (`_polish`)
BASINS = 2  # other basins of each earlier effect an edge fit of a later round is backfitted from (`restart`)


def restart(initial: Evaluator, measured: Measured, done: list[Round], current: Round, added: list[Applied],
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
    (`settle`); the settled model of least D with no parameter at an edge is kept if the candidate passes the
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
        trial, trial_fits, model = settle(initial, initial.with_base(trial), measured, trial, trial_fits, alpha,
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


def explain(initial: Evaluator, show: Evaluator, measured: Measured, done: list[Round], added: list[Applied],
            fits: list[EffectFit], failed: str, alpha: float, progress: Progress) -> Explained | None:
    """Before "none explains" (`failed` its reason): each round's close contenders, screened ones too (up to
    `ALTERNATIVES`), in place of the effect the round added, the model settled (`settle`). A mimic can score
    better on the search eyes and still leave a gap on the show eyes (a pupil shift for a head roll beside a
    corneal astigmatism, D + 2k 23.9 against 35.5, the shift's model leaving the show eyes' spread at H2): the
    model the outcome's criterion (`decide`) finds explains the data is kept, of least D + 2k if more than one
    do, with no parameter at an edge and none at its neutral value. `show` is the show eyes' evaluator without
    effects. Returns that model (`Explained`), or None."""
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
        trial, trial_fits, model = settle(initial, initial.with_base(trial), measured, trial, trial_fits, alpha,
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
        gof = goodness_of_fit(model, measured, final, k)
        outcome, reason = decide(rounds, final, after, k, gof)
        if outcome == "explained":
            best = Explained(rounds, trial, trial_fits, model, final, after, gof, reason)
    return best


def _own(done: Round) -> EffectFit:
    """The fit the round made of the effect it added (its `added` may be the backfitted one, scored with the later
    effects in the model)."""
    assert done.added is not None
    return next((f for f in done.fits if f.effect.name == done.added.effect.name), done.added)


@dataclass(frozen=True, eq=False)
class Explained:
    """A model `explain` keeps: the rounds (one with a contender in place of its added effect), the effects and
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


def drop_off(initial: Evaluator, search: Evaluator, added: list[Applied], fits: list[EffectFit], done: list[Round]
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


def settle(initial: Evaluator, search: Evaluator, measured: Measured, added: list[Applied],
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
    sigma = added_profile(initial, measured, added, progress).sigma(model.base_metrics)
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
    model (`added_profile`: two simulations per parameter, each shift within a quarter of the range), while D falls:
    a backfit refits one effect at a time, which crawls along a valley where two effects trade off (a screen tilt
    and a camera bump). Returns the effects (the list `added` itself if none moved) and their D."""
    reference = initial.experiment.reference
    D = compare(model.base_metrics, measured, reference, alpha, tests=False).D
    for _ in range(POLISH):
        profile = added_profile(initial, measured, added, progress)
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


def contend(initial: Evaluator, search: Evaluator, measured: Measured, last: Round, j: int, added: list[Applied],
            fits: list[EffectFit], alpha: float, progress: Progress
           ) -> tuple[Round, list[Applied], list[EffectFit], Evaluator]:
    """A round's contenders (`eyehil.analysis.discrepancy.workflow`, step 3), each put in place of the effect the
    round added (the `j`-th) and the model backfitted; returns the round with the scores of the backfitted models
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
        trial_added, trial_fits, model = settle(initial, model, measured, trial_added, trial_fits, alpha, progress)
        models[f.effect.name] = (score(model, trial_added), trial_added, trial_fits, model)
    name = min(models, key=lambda n: models[n][0])
    _, added, fits, search = models[name]
    verdict = last.verdict if name == own else (
        f"{last.verdict}; backfitted, {name} fits better in its place: {fits[j].applied.label()}")
    return (replace(last, added=fits[j], verdict=verdict, backfitted={n: m[0] for n, m in models.items()}),
            added, fits, search)
