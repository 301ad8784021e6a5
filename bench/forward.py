"""Benchmark: the published set-up end to end through the forward model.

100 eyes x (9 targets x 5 head positions, 2 LEDs) in the Guestrin 2006 scene plus 100 eyes x 2 eyes x
135 targets (1 LED) in the Blignaut 2014 scene; each fixation is solved, glints found and 30 pupil
points traced. Target (issue "Physics core"): <= 30 s wall on a 2-core machine.

Variant (issue 13): the same 100 eyes with toric corneas (anterior and posterior power vectors drawn
conditionally on their published parameters, `eyehil.emulator.eye.anatomy.full_anatomy` with astigmatism only);
target: within 1.5x of the symmetric eyes' time, measured in the same run.
"""

from __future__ import annotations

import time

import numpy as np

from eyehil.emulator.eye.anatomy import full_anatomy
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene

TARGET_SECONDS = 30.0
TARGET_TORIC_RATIO = 1.5


def run(repeats: int = 3) -> dict[str, float]:
    """Best-of-`repeats` wall times (s) and throughput (fixations/s), symmetric and toric eyes alternating."""
    eyes = published_eyes()
    toric = full_anatomy(eyes, np.random.default_rng(13), decentration=False, stop=False, tilt=False)
    scenes = [load_scene("guestrin2006"), load_scene("blignaut2014")]
    simulate(eyes[:2], scenes[0])  # warm-up
    simulate(toric[:2], scenes[0])
    results: dict[str, float] = {}
    total_fix = 0
    for _ in range(repeats):
        for label, batch in (("", eyes), ("toric_", toric)):
            start = time.perf_counter()
            counts = []
            for scene in scenes:
                t0 = time.perf_counter()
                f = simulate(batch, scene)
                key = f"{label}{scene.name}_s"
                results[key] = min(results.get(key, np.inf), time.perf_counter() - t0)
                counts.append(int(np.prod(f.shape)))
                assert f.valid.all()
            results[f"{label}total_s"] = min(results.get(f"{label}total_s", np.inf), time.perf_counter() - start)
            total_fix = sum(counts)
    best_total = results["total_s"]
    results["fixations"] = total_fix
    results["fixations_per_s"] = total_fix / best_total
    results["pupil_rays_per_s"] = total_fix * 30 / best_total
    results["toric_ratio"] = results["toric_total_s"] / best_total
    return results


def report(results: dict[str, float]) -> str:
    verdict = "PASS" if results["total_s"] <= TARGET_SECONDS else "FAIL"
    return (
        f"forward model, published set-up: {results['fixations']:.0f} fixations in {results['total_s']:.2f} s "
        f"(guestrin2006 {results['guestrin2006_s']:.2f} s, blignaut2014 {results['blignaut2014_s']:.2f} s); "
        f"{results['fixations_per_s']:,.0f} fixations/s, {results['pupil_rays_per_s']:,.0f} pupil rays/s; "
        f"target <= {TARGET_SECONDS:.0f} s: {verdict}; toric corneas {results['toric_total_s']:.2f} s "
        f"(guestrin2006 {results['toric_guestrin2006_s']:.2f} s, blignaut2014 {results['toric_blignaut2014_s']:.2f} s),"
        f" {results['toric_ratio']:.2f}x the symmetric eyes; target <= {TARGET_TORIC_RATIO:g}x: "
        f"{'PASS' if results['toric_ratio'] <= TARGET_TORIC_RATIO else 'FAIL'}"
    )
