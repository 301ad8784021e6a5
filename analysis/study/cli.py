"""`eyehil study fischer2023`: the replication of Fischer, van der Merwe & Vandenheever 2023, end to end.

Ray-traces the eyes through both published experiments, calibrates the host estimators, runs the
statistics and writes summary.json, per_eye.csv, report.md and figures into --out. With --anatomy full the
same eyes run a second time with the anatomy the paper left out (`eyehil.emulator.eye.anatomy.full_anatomy`,
drawn with --seed), and once more with each addition alone; the report compares the two per error category and
breaks the change down by addition (`eyehil.analysis.study.breakdown`). It takes about six times as long.

Ctrl-C stops the run at once (exit 130): the worker processes are terminated, and --out shows no file of an
unfinished run (`eyehil.analysis.output_folder`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

STUDIES = ("fischer2023",)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="replicate a published study (fischer2023)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", nargs="?", default="fischer2023", choices=STUDIES, help="the study (default fischer2023)")
    p.add_argument("--eyes", default="published",
                   help="published (the paper's 100 eyes, default) | N (a fresh Rozema draw of N eyes)")
    p.add_argument("--seed", type=int, default=2023, help="random seed for a fresh draw (default 2023)")
    p.add_argument("--out", default="study-fischer2023", help="output folder (default ./study-fischer2023)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (optional extra 'dask')")
    p.add_argument("--profile", default="study-code", choices=("study-code", "best"),
                   help="Guestrin estimator profile (default study-code: the study's code, which produced the "
                        "published numbers; best: eyehil's own)")
    p.add_argument("--compare", default="best", choices=("study-code", "best", "none"),
                   help="a second profile run on the same features and reported side by side (default best)")
    p.add_argument("--head-positions", default="study-code", choices=("study-code", "paper-text"),
                   help="Guestrin head positions: study-code (+-30 mm vertical, +-40 mm horizontal; default) or "
                        "paper-text (30 mm left/right, 40 mm forward/back)")
    p.add_argument("--anatomy", default="paper", choices=("paper", "full"),
                   help="paper (default): the published eyes' anatomy; full: also run the same eyes with "
                        "astigmatism, pupil decentration, elliptical stop and cornea tilt (drawn with --seed) and "
                        "report how each error category changes")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from eyehil.analysis.output_folder import check_output_folder, staged_folder
    from eyehil.analysis.study.findings import all_findings
    from eyehil.analysis.study.replication import run_study
    from eyehil.analysis.study.report import write_outputs
    from eyehil.analysis.study.summary import anatomy_breakdown, anatomy_summary, summarise_study
    from eyehil.emulator.eye.select import eyes_from_spec

    if args.workers is not None and args.workers < 1:
        raise ValueError("--workers must be >= 1")
    out = check_output_folder(Path(args.out))
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    if len(eyes) < 3:
        raise ValueError(f"--eyes {args.eyes}: the study's statistics need at least 3 eyes, got {len(eyes)}")
    start = time.perf_counter()
    with tqdm(total=len(eyes), unit="eye", desc="study", disable=args.quiet) as bar:
        result = run_study(eyes, profile=args.profile, compare=None if args.compare == "none" else args.compare,
                           head_positions=args.head_positions, workers=args.workers, scheduler=args.scheduler,
                           progress=bar.update)
    result.settings.update({"eyes": about, "seed": args.seed if args.eyes != "published" else None,
                            "anatomy": args.anatomy})
    summary = summarise_study(result)
    full = alone = None
    if args.anatomy == "full":
        full, alone = _full_anatomy_runs(eyes, args)
        result.settings["anatomy_seed"] = args.seed
        summary["anatomy"] = anatomy_summary(result, full)
        summary["anatomy_breakdown"] = anatomy_breakdown(result, alone, full)
    with staged_folder(out) as partial:
        written = [out / p.relative_to(partial)
                   for p in write_outputs(result, summary, partial, full, workers=args.workers)]
    findings = all_findings(summary)
    held = sum(f.holds for f in findings)
    both = ", paper and full anatomy" if full is not None else ""
    print(f"{args.name}: {len(eyes)} eyes ({about}{both}) in {time.perf_counter() - start:.1f} s")
    g = summary["guestrin"]
    print(f"  Guestrin ({g['profile']}) H1 {g['H1']['mean']:.3f} +- {g['H1']['sd']:.3f} deg, H2 "
          f"{g['H2']['mean']:.3f} +- {g['H2']['sd']:.3f} deg (published 0.36 +- 0.20)")
    c = summary.get("guestrin_compare")
    if c:
        print(f"  Guestrin ({c['profile']}, same features) H1 {c['H1']['mean']:.3f} +- {c['H1']['sd']:.3f} deg, H2 "
              f"{c['H2']['mean']:.3f} +- {c['H2']['sd']:.3f} deg")
    best = summary["blignaut"]["best_function"]
    print("  Blignaut best function: " + ", ".join(f"{c} model {v['model']} {v['mean']:.3f}" for c, v in best.items()))
    for col, r in summary.get("anatomy", {}).items():
        print(f"  {col}: paper {r['paper']['mean']:.3f} +- {r['paper']['sd']:.3f}, full {r['full']['mean']:.3f} +- "
              f"{r['full']['sd']:.3f} deg; significant (full): {', '.join(r['full']['significant']) or 'none'}")
        b = summary["anatomy_breakdown"][col]
        most, change = b["largest_change"], b["change"][b["largest_change"]]
        print(f"    {'no addition moves it by 0.005 deg; largest' if b['negligible'] else 'moved most by'}: "
              f"{most} ({change:+.3f} deg alone)")
    print(f"  published findings reproduced: {held} of {len(findings)} (see report.md)")
    for f in findings:
        if not f.holds:
            print(f"    departs: {f.claim}: {f.replicated}")
    print(f"  written: {', '.join(str(p) for p in written)}")
    return 0


def _full_anatomy_runs(eyes, args: argparse.Namespace):
    """The same eyes with `full_anatomy` (drawn with --seed) and with each of its additions alone, through the
    same study settings: (full run, {addition: run})."""
    from tqdm import tqdm

    from eyehil.analysis.study.breakdown import COMPONENTS, run_anatomy

    total = len(eyes) * (1 + len(COMPONENTS))
    with tqdm(total=total, unit="eye", desc="study, full anatomy and each addition", disable=args.quiet) as bar:
        return run_anatomy(eyes, args.seed, progress=bar.update, profile=args.profile,
                           compare=None if args.compare == "none" else args.compare,
                           head_positions=args.head_positions, workers=args.workers, scheduler=args.scheduler)
