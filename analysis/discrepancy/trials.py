"""Blind trials of the discrepancy workflow: hidden effects at random strengths, and the rates the issue asks
for (`python -m eyehil.analysis.discrepancy.trials --out DIR [--trials N] [--kind single|pair|negative|outside]`).

Each trial draws "measured" data from other eyes (a Rozema 2011 draw) with hidden effects and runs the
workflow blind on the first `search_eyes` published eyes (show: the first `show_eyes`):

- single: one effect of the catalogue (every effect in turn, cycling), strength drawn uniformly between
  `LOW` and `HIGH` of the way from its neutral value to a bound of its plausible range (random side); a
  parameter whose neutral value lies outside its range (another parameter switches the effect off: glint
  occlusion's radius) uniformly over the middle `INNER` of its range;
- pair: two different effects, each drawn so; the larger is the one that opens the larger gap alone (`sizes`:
  D of data with that effect alone, simulated on the same hidden eyes, against the search eyes' model
  without effects);
- negative: nothing hidden;
- outside: one effect hidden and removed, with its twins (`outside`), from the catalogue the workflow may use.

The model eyes (`--model-eyes`) are the published eyes by default, or a Rozema draw of their own (`model_eyes`).

Scores per trial (`score`): named (the hidden effect is the first named, outcome "explained"), both named and
in order (pairs: both named; and in the order of their sizes), nothing added (negatives), "none explains"
(outside), shrink (1 - D_after / D_before, show eyes), whether each hidden effect was added or fitted as well as
an added one or is its twin (`hidden_among_rivals`: the data could not tell it from the one named), and whether
each hidden parameter lies within the fit's 95 % interval (1.96 sigma); and whether each hidden effect is
`visible`, opening a gap of its own that some method could name. Records go to
DIR/trials-EXPERIMENT-KIND[-TAGS].jsonl, one line per trial (appended), and the run ends with its `rates` against
the issue's `TARGETS`. `--jobs N` runs N trials at once.

The trials of one process share a `Memo` of evaluated points (`memo()`): every trial of a setting runs the
workflow on the same model eyes, so the first round's screen (some 300 points, most of a trial's time) is
evaluated once per process, and a trial's record is the same as without it.
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from pathlib import Path

import numpy as np

LOW, HIGH = 0.4, 0.9
INNER = 0.8  # the middle of the range drawn for a parameter whose neutral value is outside it


@functools.cache
def memo():
    """This process's `Memo` of the workflow's evaluated points, shared by its trials (module docstring)."""
    from eyehil.analysis.discrepancy.metrics import Memo

    return Memo()


def draw(effect, rng: np.random.Generator) -> dict[str, float]:
    """Random fitted-parameter values: between LOW and HIGH of the way from neutral to a bound, or uniform over the
    middle INNER of the range where neutral is outside it."""
    out = {}
    for p in effect.fitted:
        if p.switches_off:
            sides = [b for b in (p.low, p.high) if b != p.neutral]
            bound = sides[rng.integers(len(sides))]
            out[p.name] = float(p.neutral + rng.uniform(LOW, HIGH) * (bound - p.neutral))
        else:
            out[p.name] = float(p.low + (p.high - p.low) * rng.uniform((1 - INNER) / 2, (1 + INNER) / 2))
    return out


#: `--model-eyes`: "published", the first of the 100 published eyes (the default: the workflow's own model eyes,
#: a sample that differs from the Rozema draws of the hidden eyes in absolute feature levels, docs/discrepancy.md);
#: "rozema", a Rozema 2011 draw of their own (fixed across trials, seed `MODEL_SEED` + the trials' seed), so
#: model and hidden eyes come from one population and only the hidden effect tells them apart
MODEL_EYES = ("published", "rozema")
MODEL_SEED = 99_991


def model_eyes(kind: str, count: int, seed: int):
    """The trials' model eyes (`MODEL_EYES`), `count` of them; the search uses the first ones."""
    from eyehil.emulator.eye.population import sample
    from eyehil.emulator.eye.published import published_eyes

    if kind not in MODEL_EYES:
        raise ValueError(f"model eyes must be one of {', '.join(MODEL_EYES)}, got {kind!r}")
    if kind == "published":
        return published_eyes()[:count]
    return sample(count, np.random.default_rng(MODEL_SEED + seed)).eyes


NONE = "(none)"  # the key of `sizes` for the data without hidden effects


def trial(kind: str, index: int, *, experiment: str, search_eyes: int, show_eyes: int, hidden_eyes: int,
          seed: int, features: bool = False, model: str = "published") -> dict:
    from eyehil.analysis.discrepancy.workflow import hidden_measured, run_discrepancy
    from eyehil.emulator import effects
    from eyehil.emulator.effects import Applied
    from eyehil.emulator.eye.population import sample

    rng = np.random.default_rng(seed + 1000 * index)
    names = catalogue(experiment)
    hidden: list[Applied] = []
    if kind in ("single", "outside"):
        e = effects.get(names[index % len(names)])
        hidden = [Applied.of(e, draw(e, rng))]
    elif kind == "pair":
        a, b = rng.choice(len(names), 2, replace=False)
        hidden = [Applied.of(effects.get(names[i]), draw(effects.get(names[i]), rng)) for i in (a, b)]
    removed = outside(hidden[0].effect) if kind == "outside" else set()
    allowed = [n for n in names if n not in removed]
    eyes = sample(hidden_eyes, np.random.default_rng(seed + 7 + index)).eyes
    conditions = recording_conditions(experiment) if features else None
    measured = hidden_measured(hidden, eyes=eyes, experiment=experiment, conditions=conditions,
                               seed=seed + 3 + index)
    show = model_eyes(model, max(show_eyes, search_eyes), seed)
    gaps = sizes(hidden, eyes, experiment, conditions, seed + 3 + index, show[:search_eyes], seed) if hidden else {}
    named = [a.effect.name for a in hidden]
    order = sorted(named, key=lambda name: -gaps[name])
    start = time.perf_counter()
    result = run_discrepancy(measured, eyes=show[:show_eyes], search_eyes=show[:search_eyes],
                             effect_names=allowed, rounds=2, seed=seed, memo=memo())
    record = {"kind": kind, "index": index, "experiment": experiment, "features": features, "model_eyes": model,
              "hidden": [a.label() for a in hidden], "hidden_order": order, "removed": sorted(removed),
              "sizes": gaps,
              "hidden_values": {a.effect.name: dict(a.values) for a in hidden}, "seconds": time.perf_counter() - start,
              **result.summary()}
    return {**record, **score(record, result, hidden)}


def _host(experiment: str):
    from eyehil.analysis.discrepancy.metrics import experiment as named_experiment
    from eyehil.emulator.scene import load_scene

    chosen = named_experiment(experiment)
    return chosen, load_scene(chosen.scene)


def recording_conditions(experiment: str) -> list[str]:
    """The conditions of `experiment` as from recordings: its gaze conditions and every feature condition."""
    from eyehil.analysis.discrepancy.recording import feature_names

    chosen, host = _host(experiment)
    return [*chosen.diagnostic_conditions(host), *feature_names(host.head_positions)]


def catalogue(experiment: str) -> list[str]:
    """The effects a trial of `experiment` hides and the workflow may name: the whole catalogue, less the effects
    acting only at validation head positions where the experiment has one head position (Blignaut 2014; the rule
    of `rounds.candidates`)."""
    from eyehil.emulator import effects

    one_session = len(_host(experiment)[1].head_positions) < 2
    return [n for n in effects.names() if not (one_session and effects.get(n).validation_only)]


def outside(effect) -> set[str]:
    """The effects an "outside" trial removes from the catalogue: the hidden one and its `twins`, which no data can
    tell from it (left in, a twin explains the data as well as the hidden effect would: the trial would test
    identifiability, not the "none explains" criterion)."""
    return {effect.name, *effect.twins}


def sizes(hidden, eyes, experiment: str, conditions, noise_seed: int, search_eyes, seed: int) -> dict[str, float]:
    """D of data with each hidden effect alone (the same hidden eyes and noise seed as the trial's data) against the
    model without effects on the search eyes, by effect name; and under "(none)" the D of the same data with no
    effect, the floor from the eyes and the noise alone, against which an effect's own size shows."""
    from eyehil.analysis.discrepancy.metrics import Evaluator
    from eyehil.analysis.discrepancy.stats import compare
    from eyehil.analysis.discrepancy.workflow import hidden_measured

    base = Evaluator(experiment, search_eyes, seed=seed)

    def gap(applied: list) -> float:
        data = hidden_measured(applied, eyes=eyes, experiment=experiment, conditions=conditions, seed=noise_seed)
        return compare(base.base_metrics, data, base.experiment.reference, tests=False).D

    return {**{a.effect.name: gap([a]) for a in hidden}, NONE: gap([])}


def visible(gaps: dict[str, float], applied) -> bool:
    """Whether a hidden effect opens a gap of its own: its D alone exceeds the floor of no effect (`sizes`) by more
    than the 95 % point of chi-square(k), k its fitted parameters. No method can name an effect that does not."""
    from scipy.stats import chi2

    return bool(gaps[applied.effect.name] - gaps[NONE] > chi2.ppf(0.95, len(applied.effect.fitted)))


def score(record: dict, result, hidden) -> dict:
    """The trial's scores (module docstring)."""
    named = record["named_effects"]
    truth = [a.effect.name for a in hidden]
    out: dict = {"shrink": result.shrink, "visible": [visible(record["sizes"], a) for a in hidden]}
    if len(hidden) == 2:
        out["named_both"] = sorted(named) == sorted(truth)
        out["in_order"] = named == record["hidden_order"]
    elif hidden:
        out["named"] = bool(named) and named[0] == truth[0] and record["outcome"] == "explained"
    out["added_nothing"] = not result.added
    by_added = record.get("rivals", {})  # added effect -> its rivals
    rivals = set(by_added).union(*by_added.values(), *record.get("twins", {}).values())
    out["hidden_among_rivals"] = [name in rivals for name in truth]
    covered = []
    for a in hidden:
        fit = record["parameters"].get(a.effect.name)
        if fit:
            for p, v in fit.items():
                ci = v["ci95"]
                covered.append(bool(ci is not None and np.isfinite(ci) and abs(v["value"] - a.values[p]) <= ci))
    out["covered"] = covered
    return out


#: The issue's targets for `rates` (fractions of trials; issue 18): singles named, pairs named in order, nothing
#: added on negatives, "none explains" for an effect outside the catalogue, shrink >= 70 % where the hidden effects
#: were named, hidden parameters within the fit's 95 % interval.
TARGETS = {"singles_named": 0.9, "pairs_in_order": 0.7, "negatives_nothing_added": 1.0,
           "outside_none_explains": 1.0, "shrink_70": 1.0, "covered": 0.8}


def rates(records: list[dict]) -> dict[str, list[int]]:
    """[hits, trials] of every rate of `TARGETS` over trial records, and of naming among the trials whose hidden
    effects are all `visible` ("..._of_visible"); a rate without trials is [0, 0]."""
    def kind(name: str) -> list[dict]:
        return [r for r in records if r["kind"] == name]

    def count(hits) -> list[int]:
        hits = [bool(h) for h in hits]
        return [sum(hits), len(hits)]

    singles, pairs = kind("single"), kind("pair")
    named = [r for r in singles if r.get("named")] + [r for r in pairs if r.get("named_both")]
    return {"singles_named": count(r["named"] for r in singles),
            "singles_named_of_visible": count(r["named"] for r in singles if all(r.get("visible", [True]))),
            "pairs_in_order": count(r["in_order"] for r in pairs),
            "pairs_in_order_of_visible": count(r["in_order"] for r in pairs if all(r.get("visible", [True]))),
            "negatives_nothing_added": count(r["added_nothing"] for r in kind("negative")),
            "outside_none_explains": count(r["outcome"] == "none explains" for r in kind("outside")),
            "outside_none_explains_of_visible": count(r["outcome"] == "none explains" for r in kind("outside")
                                                      if all(r.get("visible", [True]))),
            "shrink_70": count(r["shrink"] >= 0.7 for r in named),
            "covered": count(c for r in singles + pairs for c in r["covered"])}


def met(counts: dict[str, list[int]]) -> dict[str, bool]:
    """Each rate of `TARGETS` that has trials: whether it reaches its target."""
    return {k: counts[k][0] >= target * counts[k][1] - 1e-9 for k, target in TARGETS.items() if counts[k][1]}


def run_trials(kind: str, indices, *, jobs: int = 1, **settings):
    """`trial(kind, i, **settings)` for every i of `indices`, in `jobs` processes; yields the records as they end."""
    from eyehil.parallel import worker_pool

    if jobs < 2:
        for i in indices:
            yield trial(kind, i, **settings)
        return
    from concurrent.futures import as_completed

    with worker_pool(jobs) as pool:
        for future in as_completed([pool.submit(trial, kind, i, **settings) for i in indices]):
            yield future.result()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="discrepancy-trials")
    parser.add_argument("--kind", default="single", choices=("single", "pair", "negative", "outside"))
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--first", type=int, default=0, help="index of the first trial")
    parser.add_argument("--jobs", type=int, default=1, help="trials run at once, each in its own process")
    parser.add_argument("--experiment", default="guestrin2006")
    parser.add_argument("--search-eyes", type=int, default=8)
    parser.add_argument("--show-eyes", type=int, default=20)
    parser.add_argument("--hidden-eyes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--features", action="store_true",
                        help="measured data as from recordings: feature conditions besides the gaze errors")
    parser.add_argument("--model-eyes", default="published", choices=MODEL_EYES,
                        help="the workflow's model eyes: the published eyes (default) or a Rozema draw of their own")
    args = parser.parse_args(argv)
    if args.trials < 1 or args.first < 0 or args.jobs < 1:
        parser.error("--trials and --jobs must be at least 1, --first at least 0")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tags = ("-features" if args.features else "") + ("" if args.model_eyes == "published" else f"-{args.model_eyes}")
    path = out / f"trials-{args.experiment}-{args.kind}{tags}.jsonl"
    settings = {"experiment": args.experiment, "search_eyes": args.search_eyes, "show_eyes": args.show_eyes,
                "hidden_eyes": args.hidden_eyes, "seed": args.seed, "features": args.features,
                "model": args.model_eyes}
    records = []
    for rec in run_trials(args.kind, range(args.first, args.first + args.trials), jobs=args.jobs, **settings):
        records.append(rec)
        with path.open("a", encoding="utf-8") as f:
            f.write(json.dumps(rec, default=float) + "\n")
        print(json.dumps({k: rec[k] for k in ("kind", "index", "hidden", "outcome", "named_effects", "hidden_order",
                                               "in_order", "shrink", "covered", "visible", "seconds") if k in rec},
                         default=float), flush=True)
    counts = rates(records)
    verdict = met(counts)
    print("rates of this run: " + "; ".join(f"{k} {h} of {n}" + (f" ({'met' if verdict[k] else 'NOT met'})"
                                                                   if k in verdict else "")
                                             for k, (h, n) in counts.items() if n), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
