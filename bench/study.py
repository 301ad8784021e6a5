"""Benchmark: `eyehil study fischer2023` end to end on the 100 published eyes (both experiments, all
calibrations and statistics; no figures). Target (issue "Host gaze estimation ..."): <= 60 s wall on
a 2-core machine, with the default local process pool.
"""

from __future__ import annotations

import time

from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.runner import default_workers
from eyehil.analysis.study.summary import summarise_study
from eyehil.emulator.eye.published import published_eyes

TARGET_SECONDS = 60.0


def run(repeats: int = 3) -> dict[str, float]:
    eyes = published_eyes()
    best = float("inf")
    for _ in range(max(1, min(repeats, 2))):  # a study run is long: at most two
        start = time.perf_counter()
        summarise_study(run_study(eyes))
        best = min(best, time.perf_counter() - start)
    return {"seconds": best, "eyes": len(eyes), "workers": default_workers()}


def report(results: dict[str, float]) -> str:
    verdict = "PASS" if results["seconds"] <= TARGET_SECONDS else "FAIL"
    return (f"study fischer2023, {results['eyes']:.0f} published eyes, {results['workers']:.0f} workers: "
            f"{results['seconds']:.1f} s; target <= {TARGET_SECONDS:.0f} s: {verdict}")
