"""Benchmark: the published set-up end to end through the forward model.

100 eyes x (9 targets x 5 head positions, 2 LEDs) in the Guestrin 2006 scene plus 100 eyes x 2 eyes x
135 targets (1 LED) in the Blignaut 2014 scene: 31,500 fixations, each solved, its glints found and 30 pupil
points traced.

Cases, measured in turn within each repeat so that they share the machine's load:
- `previous`: one process, the pupil solve by the forward-difference Newton (`pupil_solver="newton"`, the
  implementation before commit 9e352ca);
- `one core`: one process, the current implementation (Broyden's method seeded by the pupil centre);
- `two cores`: the current implementation on a warm pool of 2 worker processes (`eyehil.parallel.worker_pool`,
  started and warmed up before the clock starts), each scene's eyes split in two; the features are sent back
  to this process, as `eyehil simulate` and the study receive them;
- `toric`: one process, the same 100 eyes with toric corneas (anterior and posterior power vectors drawn
  conditionally on their published parameters, `eyehil.emulator.eye.anatomy.full_anatomy` with astigmatism
  only).

Targets: the set-up in <= 1.0 s on 2 cores, >= 30,000 fixations/s (issue 16); toric corneas within 1.5x of
the symmetric eyes in one process (issue 13).
"""

from __future__ import annotations

import time

import numpy as np

from eyehil.emulator.eye.anatomy import full_anatomy
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene
from eyehil.parallel import worker_pool

TARGET_FIXATIONS_PER_S = 30_000.0  # issue 16: 31,500 fixations in <= 1.0 s on 2 cores
TARGET_TORIC_RATIO = 1.5  # issue 13
SCENES = ("guestrin2006", "blignaut2014")
WORKERS = 2


def _simulate_part(eyes: EyeModel, scene_name: str, pupil_solver: str = "secant") -> Features:
    """One worker's share: `simulate` of `eyes` in the preset `scene_name`."""
    return simulate(eyes, load_scene(scene_name), pupil_solver=pupil_solver)


def _in_process(eyes: EyeModel, pupil_solver: str) -> tuple[float, int]:
    """Wall time (s) and fixations of the set-up in this process."""
    start, fixations = time.perf_counter(), 0
    for name in SCENES:
        f = _simulate_part(eyes, name, pupil_solver)
        assert f.valid.all()
        fixations += int(np.prod(f.shape))
    return time.perf_counter() - start, fixations


def _on_pool(pool, eyes: EyeModel) -> tuple[float, int]:
    """Wall time (s) and fixations of the set-up split over the pool's workers, results gathered here."""
    halves = np.array_split(np.arange(len(eyes)), WORKERS)
    start = time.perf_counter()
    futures = [pool.submit(_simulate_part, eyes[part], name) for name in SCENES for part in halves]
    parts = [future.result() for future in futures]
    elapsed = time.perf_counter() - start
    assert all(f.valid.all() for f in parts)
    return elapsed, sum(int(np.prod(f.shape)) for f in parts)


def run(repeats: int = 3) -> dict[str, float]:
    """Best-of-`repeats` wall time (s) of each case, the cases interleaved within each repeat."""
    eyes = published_eyes()
    toric = full_anatomy(eyes, np.random.default_rng(13), decentration=False, stop=False, tilt=False)
    for warm in (eyes[:2], toric[:2]):
        simulate(warm, load_scene(SCENES[0]))
    results: dict[str, float] = {}
    with worker_pool(WORKERS) as pool:
        for _ in range(WORKERS):  # import and warm up every worker before the clock starts
            pool.submit(_simulate_part, eyes[:2], SCENES[0]).result()
        for _ in range(repeats):
            cases = {
                "previous": lambda: _in_process(eyes, "newton"),
                "one_core": lambda: _in_process(eyes, "secant"),
                "two_cores": lambda: _on_pool(pool, eyes),
                "toric": lambda: _in_process(toric, "secant"),
            }
            for label, case in cases.items():
                seconds, fixations = case()
                results[f"{label}_s"] = min(results.get(f"{label}_s", np.inf), seconds)
                results["fixations"] = fixations
    n = results["fixations"]
    for label in ("previous", "one_core", "two_cores"):
        results[f"{label}_per_s"] = n / results[f"{label}_s"]
    results["speed_up"] = results["previous_s"] / results["one_core_s"]
    results["toric_ratio"] = results["toric_s"] / results["one_core_s"]
    return results


def report(results: dict[str, float]) -> str:
    fast = results["two_cores_per_s"] >= TARGET_FIXATIONS_PER_S
    toric_ok = results["toric_ratio"] <= TARGET_TORIC_RATIO
    return (
        f"forward model, published set-up ({results['fixations']:,.0f} fixations, 30 pupil points each): "
        f"previous implementation {results['previous_s']:.2f} s ({results['previous_per_s']:,.0f}/s); now "
        f"{results['one_core_s']:.2f} s on one core ({results['one_core_per_s']:,.0f}/s, "
        f"{results['speed_up']:.2f}x the previous) and {results['two_cores_s']:.2f} s on {WORKERS} worker "
        f"processes ({results['two_cores_per_s']:,.0f}/s); target >= {TARGET_FIXATIONS_PER_S:,.0f}/s on 2 cores: "
        f"{'PASS' if fast else 'FAIL'}; toric corneas {results['toric_s']:.2f} s on one core, "
        f"{results['toric_ratio']:.2f}x the symmetric eyes; target <= {TARGET_TORIC_RATIO:g}x: "
        f"{'PASS' if toric_ok else 'FAIL'}"
    )
