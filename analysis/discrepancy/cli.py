"""`eyehil discrepancy`: find where the simulation and measured data disagree, name the missing effect, add it,
and show the gap shrink (analysis/discrepancy/workflow.py; docs/discrepancy.md).

Measured data: a built-in real data set (guestrin2006, the default: Guestrin & Eizenman 2006's 4 subjects;
blignaut2014: Blignaut 2014's best-function means), a file in the eyehil.measured/1 JSON format, a folder of
eyehil recordings (one *.jsonl per subject, compared at the gaze-error and the feature level; either experiment,
named by the recordings' "scene" or --experiment), or --hidden EFFECT=VALUE: data simulated on other eyes (a
Rozema 2011 draw) with an effect the workflow is not told about. Writes summary.json, result.json, measured.json,
report.md and discrepancy.png into --out. Progress of every stage goes to stderr (--quiet: none).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

SEARCH_EYES = 20  # the default number of search eyes (the first of the model eyes)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("discrepancy", help="find, name and add the effect missing from the simulation",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--measured", default=None, metavar="FILE|NAME",
                     help="measured data: guestrin2006 (default), blignaut2014, a JSON file, or a folder of "
                          "recordings (one *.jsonl per subject)")
    src.add_argument("--hidden", action="append", default=None, metavar="EFFECT=VALUE",
                     help="simulate measured data with this effect, e.g. pupil_change=-0.7 (repeatable)")
    p.add_argument("--experiment", default=None, help="experiment of --hidden data (default guestrin2006) or of a "
                   "folder of recordings (default: the scene their headers name, else guestrin2006)")
    p.add_argument("--out", default="discrepancy", help="output folder (default ./discrepancy)")
    p.add_argument("--eyes", default="published", help="model eyes: published (default) | sample:N | N")
    p.add_argument("--search-eyes", type=int, default=None,
                   help=f"eyes used in the search (first N of --eyes; default {SEARCH_EYES}, or all if fewer)")
    p.add_argument("--hidden-eyes", type=int, default=30, help="eyes of --hidden data (default 30)")
    p.add_argument("--hidden-seed", type=int, default=7, help="seed of the --hidden eyes and noise (default 7)")
    p.add_argument("--seed", type=int, default=0, help="seed of the model eyes' draw and noise (default 0)")
    p.add_argument("--rounds", type=int, default=2, help="find-name-add rounds at most (default 2)")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise significance level (default 0.05)")
    p.add_argument("--effects", default=None, help="comma-separated effect names to consider (default: all)")
    p.add_argument("--exclude", default=None, help="comma-separated effect names to leave out of the catalogue")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def _measured(args: argparse.Namespace):
    from eyehil.analysis.discrepancy.measured import measured_from_spec
    from eyehil.analysis.discrepancy.workflow import hidden_measured
    from eyehil.emulator.effects import parse
    from eyehil.emulator.eye.population import sample

    if not args.hidden:
        return measured_from_spec(args.measured or "guestrin2006", args.experiment)
    import numpy as np

    hidden = [parse(h) for h in args.hidden]
    eyes = sample(args.hidden_eyes, np.random.default_rng(args.hidden_seed)).eyes
    return hidden_measured(hidden, eyes=eyes, experiment=args.experiment or "guestrin2006", seed=args.hidden_seed)


def _check(args: argparse.Namespace) -> None:
    if (args.search_eyes is not None and args.search_eyes < 3) or args.hidden_eyes < 3:
        raise ValueError("--search-eyes and --hidden-eyes must be >= 3")
    if args.rounds < 1 or not 0 < args.alpha < 1:
        raise ValueError("--rounds must be >= 1 and --alpha in (0, 1)")
    if args.workers is not None and args.workers < 1:
        raise ValueError("--workers must be >= 1")


def _search_eyes(asked: int | None, available: int) -> int:
    """The number of search eyes: `asked` (an error beyond the model eyes), else `SEARCH_EYES` or all of them."""
    if available < 3:
        raise ValueError(f"--eyes gives {available} model eyes: the workflow needs >= 3")
    if asked is None:
        return min(SEARCH_EYES, available)
    if asked > available:
        raise ValueError(f"--search-eyes {asked} exceeds the {available} model eyes of --eyes")
    return asked


class BarProgress:
    """One tqdm bar per stage of the workflow, on stderr (`eyehil.analysis.discrepancy.rounds.Progress`)."""

    def __init__(self, disable: bool):
        self.disable, self.bar = disable, None

    def stage(self, label: str, total: int) -> None:
        from tqdm import tqdm

        self.close()
        self.bar = tqdm(total=total, desc=label, unit="step", disable=self.disable, leave=True)

    def advance(self, n: int) -> None:
        if self.bar is not None:
            self.bar.total = max(self.bar.total, self.bar.n + n)
            self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def run(args: argparse.Namespace) -> int:
    from eyehil.analysis.discrepancy.report import write_outputs
    from eyehil.analysis.discrepancy.workflow import run_discrepancy
    from eyehil.analysis.output_folder import check_output_folder, staged_folder
    from eyehil.emulator import effects as registry
    from eyehil.emulator.eye.select import eyes_from_spec
    from eyehil.parallel import default_workers

    _check(args)
    out = check_output_folder(Path(args.out))
    names = [n.strip() for n in args.effects.split(",")] if args.effects else registry.names()
    excluded = [n.strip() for n in args.exclude.split(",")] if args.exclude else []
    for n in [*names, *excluded]:
        registry.get(n)
    names = [n for n in names if n not in excluded]
    progress = BarProgress(args.quiet)
    start = time.perf_counter()
    progress.stage("measured data", 1)
    measured = _measured(args)
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    progress.advance(1)
    result = run_discrepancy(measured, eyes=eyes, search_eyes=eyes[:_search_eyes(args.search_eyes, len(eyes))],
                             effect_names=names, rounds=args.rounds, alpha=args.alpha, seed=args.seed,
                             workers=args.workers or default_workers(), progress=progress)
    progress.stage("writing the report and figure", 1)
    with staged_folder(out) as partial:  # --out shows no file of an unfinished run
        written = [out / p.relative_to(partial) for p in write_outputs(result, partial)]
    progress.advance(1)
    progress.close()
    _print(result, about, time.perf_counter() - start, written)
    return 0


def _print(result, about: str, seconds: float, written) -> None:
    print(f"discrepancy {result.settings['experiment']}: {result.measured.source}")
    print(f"  model eyes: {about}; {result.settings['evaluations']} evaluations in {seconds:.1f} s")
    for i, r in enumerate(result.rounds, start=1):
        sig = ", ".join(f"{g.compared} ({g.difference:+.3f} deg, Holm p {g.p_holm:.2g})" for g in r.before.significant)
        print(f"  round {i}: D {r.before.D:.2f}; significant gaps: {sig or 'none'}")
        for f in r.fits[:3]:
            print(f"    {f.applied.label()}: D {f.D:.2f} ({100 * f.explained:.0f} % explained)")
        print(f"    {r.verdict}")
    named = ", ".join(a.label() for a in result.named) or "none"
    print(f"  outcome: {result.outcome}; named (largest first): {named}")
    print(f"    {result.reason}")
    left = ", ".join(g.compared for g in result.after.significant) or "none"
    print(f"  show ({result.settings['eyes']} eyes): D {result.before.D:.2f} -> {result.after.D:.2f}; "
          f"significant gaps left: {left}")
    if result.measured.extra.get("hidden"):
        print(f"  hidden truth: {', '.join(result.measured.extra['hidden'])}")
    print(f"  written: {', '.join(str(p) for p in written)}")
