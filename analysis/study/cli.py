"""`eyehil study fischer2023`: the replication of Fischer, van der Merwe & Vandenheever 2023, end to end.

Ray-traces the eyes through both published experiments, calibrates the host estimators, runs the
statistics and writes summary.json, per_eye.csv, report.md and figures into --out.
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
    p.add_argument("--n1", type=float, default=1.3375,
                   help="corneal index of the Guestrin estimator (paper text 1.3375; the study code used 1.376)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from eyehil.analysis.study.findings import all_findings
    from eyehil.analysis.study.replication import run_study
    from eyehil.analysis.study.report import write_outputs
    from eyehil.analysis.study.summary import summarise_study
    from eyehil.emulator.eye.select import eyes_from_spec

    if args.workers is not None and args.workers < 1:
        raise ValueError("--workers must be >= 1")
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    start = time.perf_counter()
    with tqdm(total=len(eyes), unit="eye", desc="study", disable=args.quiet) as bar:
        result = run_study(eyes, n1=args.n1, workers=args.workers, scheduler=args.scheduler, progress=bar.update)
    result.settings.update({"eyes": about, "seed": args.seed if args.eyes != "published" else None})
    summary = summarise_study(result)
    written = write_outputs(result, summary, Path(args.out))
    findings = all_findings(summary)
    held = sum(f.holds for f in findings)
    print(f"{args.name}: {len(eyes)} eyes ({about}) in {time.perf_counter() - start:.1f} s")
    g = summary["guestrin"]
    print(f"  Guestrin H1 {g['H1']['mean']:.3f} +- {g['H1']['sd']:.3f} deg, H2 {g['H2']['mean']:.3f} +- "
          f"{g['H2']['sd']:.3f} deg (published 0.36 +- 0.20)")
    best = summary["blignaut"]["best_function"]
    print("  Blignaut best function: " + ", ".join(f"{c} model {v['model']} {v['mean']:.3f}" for c, v in best.items()))
    print(f"  published findings reproduced: {held} of {len(findings)} (see report.md)")
    for f in findings:
        if not f.holds:
            print(f"    departs: {f.claim}: {f.replicated}")
    print(f"  written: {', '.join(str(p) for p in written)}")
    return 0
