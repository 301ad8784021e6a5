"""Benchmark: `eyehil study fischer2023` end to end on the 100 published eyes: both experiments, both
Guestrin profiles (study-code and best), all calibrations, statistics, report and figures. Target
(issue 16): <= 10 s wall on a 2-core machine with the default local process pool.

The same run also times the previous implementation (per-eye estimators: scipy least_squares per eye,
one lstsq per Blignaut fit, chunks of 10 eyes) on the like-for-like work (one profile, "best", with
figures) and prints the ratio to the batched estimators on the same work.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from analysis.report import write_outputs
from analysis.runner import default_workers
from analysis.study import run_study
from analysis.summary import summarise_study
from emulator.eye.published import published_eyes

TARGET_SECONDS = 10.0


def _end_to_end(eyes, out: Path, **kwargs) -> float:
    start = time.perf_counter()
    result = run_study(eyes, **kwargs)
    write_outputs(result, summarise_study(result), out)
    return time.perf_counter() - start


def run(repeats: int = 3) -> dict[str, float]:
    eyes = published_eyes()
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(max(1, min(repeats, 2))):  # a study run is long: at most two
            best = min(best, _end_to_end(eyes, Path(tmp) / f"default{i}"))
        batched = _end_to_end(eyes, Path(tmp) / "batched", profile="best", compare=None)
        previous = _end_to_end(eyes, Path(tmp) / "previous", profile="best", compare=None, batched=False)
    return {"seconds": best, "eyes": len(eyes), "workers": default_workers(), "batched_best_only": batched,
            "previous_best_only": previous}


def report(results: dict[str, float]) -> str:
    verdict = "PASS" if results["seconds"] <= TARGET_SECONDS else "FAIL"
    return (f"study fischer2023, {results['eyes']:.0f} published eyes, {results['workers']:.0f} workers, two "
            f"profiles, figures: {results['seconds']:.1f} s; target <= {TARGET_SECONDS:.0f} s: {verdict}. "
            f"Like for like (profile best only, figures): batched {results['batched_best_only']:.1f} s, previous "
            f"per-eye estimators {results['previous_best_only']:.1f} s, "
            f"{results['previous_best_only'] / results['batched_best_only']:.1f}x")
