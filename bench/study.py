"""Benchmark: `eyehil study fischer2023` end to end on the 100 published eyes: both experiments, both
Guestrin profiles (study-code and best), all calibrations, statistics, report and figures. Target
(issue 16): <= 10 s wall on a 2-core machine with the default local process pool.

The same run also times the previous implementation (per-eye estimators: scipy least_squares per eye,
one lstsq per Blignaut fit, chunks of 10 eyes) on the like-for-like work (one profile, "best", with
figures) and prints the ratio to the batched estimators on the same work.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.report import write_outputs
from eyehil.analysis.study.summary import summarise_study
from eyehil.emulator.eye.published import published_eyes
from eyehil.parallel import default_workers

TARGET_SECONDS = 10.0


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _end_to_end(eyes, out: Path, **kwargs) -> tuple[float, float]:
    """(wall s, CPU s of this process and its finished workers) of a run with its outputs and figures."""
    start, cpu = time.perf_counter(), _cpu()
    result = run_study(eyes, **kwargs)
    write_outputs(result, summarise_study(result), out)
    return time.perf_counter() - start, _cpu() - cpu


def run(repeats: int = 3) -> dict[str, float]:
    eyes = published_eyes()
    best, best_cpu = float("inf"), float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(max(1, min(repeats, 2))):  # a study run is long: at most two
            wall, cpu = _end_to_end(eyes, Path(tmp) / f"default{i}")
            best, best_cpu = min(best, wall), min(best_cpu, cpu)
        batched, batched_cpu = _end_to_end(eyes, Path(tmp) / "batched", profile="best", compare=None)
        previous, previous_cpu = _end_to_end(eyes, Path(tmp) / "previous", profile="best", compare=None,
                                             batched=False)
    return {"seconds": best, "cpu_seconds": best_cpu, "eyes": len(eyes), "workers": default_workers(),
            "batched_best_only": batched, "previous_best_only": previous, "batched_cpu": batched_cpu,
            "previous_cpu": previous_cpu}


def report(results: dict[str, float]) -> str:
    verdict = "PASS" if results["seconds"] <= TARGET_SECONDS else "FAIL"
    return (f"study fischer2023, {results['eyes']:.0f} published eyes, {results['workers']:.0f} workers, two "
            f"profiles, figures: {results['seconds']:.1f} s wall ({results['cpu_seconds']:.1f} s CPU); target <= "
            f"{TARGET_SECONDS:.0f} s: {verdict}. Like for like (profile best only, figures): batched "
            f"{results['batched_best_only']:.1f} s wall / {results['batched_cpu']:.1f} s CPU, previous per-eye "
            f"estimators {results['previous_best_only']:.1f} s / {results['previous_cpu']:.1f} s CPU: "
            f"{results['previous_best_only'] / results['batched_best_only']:.1f}x wall, "
            f"{results['previous_cpu'] / results['batched_cpu']:.1f}x CPU")
