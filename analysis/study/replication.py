"""The replication of Fischer, van der Merwe & Vandenheever 2023 (J Eye Mov Res 16(3)).

`run_study(eyes)` ray-traces every eye through both experiments (Guestrin 2006: 9 targets x 5 head
positions, one eye, two LEDs; Blignaut 2014: 135 targets, both eyes, one LED), calibrates the host
estimators exactly as the study did, and gathers per-eye errors; `analyse(result)` computes the
published statistics. Eyes are processed in parallel chunks (`eyehil.analysis.study.runner`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eyehil.analysis.study import experiments
from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.analysis.study.runner import run_chunks
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import Scene, load_scene

CHUNK_EYES = 10


@dataclass
class StudyResult:
    """Per-eye results of both experiments (degrees) and how the run was made."""

    eyes: EyeModel
    h1: np.ndarray
    h2: np.ndarray
    guestrin_params: np.ndarray  # (E, 4) R, K, alpha, beta
    blignaut_errors: np.ndarray  # (E, 8, 6)
    failures: list[str]
    counts: dict[str, int]
    settings: dict[str, Any] = field(default_factory=dict)


def run_chunk(eyes: EyeModel, *, guestrin_scene: Scene, blignaut_scene: Scene, n1: float) -> dict[str, Any]:
    """Both experiments for one chunk of eyes (runs in a worker process)."""
    g_features = simulate(eyes, guestrin_scene)
    g = experiments.guestrin(g_features, guestrin_scene, n1=n1)
    b_features = simulate(eyes, blignaut_scene)
    b = experiments.blignaut(b_features, blignaut_scene)
    counts = {f"guestrin_{k}": v for k, v in g_features.counts().items()}
    counts.update({f"blignaut_{k}": v for k, v in b_features.counts().items()})
    failures = g.failures + [f"blignaut model {k} {c}: {why}" for (k, c), why in b.failures.items()]
    return {"h1": g.h1, "h2": g.h2, "params": g.params, "errors": b.errors, "failures": failures, "counts": counts}


def run_study(
    eyes: EyeModel,
    *,
    n1: float = 1.3375,
    workers: int | None = None,
    scheduler: str | None = None,
    progress=None,
    guestrin_scene: Scene | None = None,
    blignaut_scene: Scene | None = None,
) -> StudyResult:
    """Both experiments on every eye; `n1` is the corneal index of the Guestrin estimator."""
    eyes = eyes.as_batch()
    g_scene = guestrin_scene or load_scene("guestrin2006")
    b_scene = blignaut_scene or load_scene("blignaut2014")
    chunks = [eyes[a : a + CHUNK_EYES] for a in range(0, len(eyes), CHUNK_EYES)]
    start = time.perf_counter()
    parts = run_chunks(run_chunk, chunks, sizes=[len(c) for c in chunks], workers=workers, scheduler=scheduler,
                       progress=progress, guestrin_scene=g_scene, blignaut_scene=b_scene, n1=n1)
    counts: dict[str, int] = {}
    for part in parts:
        for k, v in part["counts"].items():
            counts[k] = counts.get(k, 0) + v
    failures = sorted({f for part in parts for f in part["failures"]})
    return StudyResult(
        eyes=eyes, h1=np.concatenate([p["h1"] for p in parts]), h2=np.concatenate([p["h2"] for p in parts]),
        guestrin_params=np.concatenate([p["params"] for p in parts]),
        blignaut_errors=np.concatenate([p["errors"] for p in parts]), failures=failures, counts=counts,
        settings={"n1": n1, "guestrin_scene": g_scene.name, "blignaut_scene": b_scene.name,
                  "media": g_scene.media, "wavelength_nm": g_scene.wavelength_nm,
                  "seconds": time.perf_counter() - start, "configurations": list(CONFIGURATIONS)},
    )
