"""The replication of Fischer, van der Merwe & Vandenheever 2023 (J Eye Mov Res 16(3)).

`run_study(eyes)` ray-traces every eye through both experiments (Guestrin 2006: 9 targets x 5 head
positions, one eye, two LEDs; Blignaut 2014: 135 targets, both eyes, one LED), calibrates the host
estimators and gathers per-eye errors; `eyehil.analysis.study.summary` computes the published statistics. Eyes are
processed in parallel chunks of `CHUNK_EYES` (`eyehil.parallel`), each chunk's calibrations batched
across its eyes (`eyehil.drivers.gaze.guestrin_batch`, `eyehil.drivers.gaze.blignaut.fit_form_many`).

Guestrin estimator: `profile` (default "study-code", the estimator of the study's public code, which
produced the published numbers) and `compare` (default "best", eyehil's own) run on the same features
(`eyehil.drivers.gaze.guestrin.PROFILES`). Head positions (`HEAD_POSITIONS`): "study-code" (the study's code,
tests/environment_gues.m: +-30 mm vertical and +-40 mm horizontal, no depth move; the default, since
it produced the published numbers) or "paper-text" (the paper's text: 30 mm left and right, 40 mm
forward and back; the guestrin2006 scene's own positions).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from eyehil.analysis.study import experiments
from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.drivers.gaze.guestrin import PROFILES
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import HeadPose, Scene, load_scene
from eyehil.parallel import run_chunks

CHUNK_EYES = 50

#: Named head-position sets of the Guestrin experiment (head frame mm: x to the subject's left, y up, z ahead).
HEAD_POSITIONS: dict[str, tuple[HeadPose, ...] | None] = {
    "study-code": (HeadPose("central"), HeadPose("up 30 mm", y=30.0), HeadPose("down 30 mm", y=-30.0),
                   HeadPose("left 40 mm", x=40.0), HeadPose("right 40 mm", x=-40.0)),
    "paper-text": None,  # the guestrin2006 scene's positions: +-30 mm sideways, +-40 mm in depth
}


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
    #: every profile run, by name: {"h1", "h2", "params"} (the main profile's are also h1, h2, guestrin_params)
    profiles: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)


def run_chunk(eyes: EyeModel, *, guestrin_scene: Scene, blignaut_scene: Scene, profiles: tuple[str, ...],
              batched: bool = True) -> dict[str, Any]:
    """Both experiments for one chunk of eyes (runs in a worker process); `batched=False` runs the
    per-eye estimators (the previous implementation, kept as the reference)."""
    g_features = simulate(eyes, guestrin_scene)
    runs = {}
    for name in profiles:
        if batched:
            runs[name] = experiments.guestrin_batched(g_features, guestrin_scene, PROFILES[name])
        else:
            runs[name] = experiments.guestrin(g_features, guestrin_scene, options=PROFILES[name])
    b_features = simulate(eyes, blignaut_scene)
    b = (experiments.blignaut_batched if batched else experiments.blignaut)(b_features, blignaut_scene)
    counts = {f"guestrin_{k}": v for k, v in g_features.counts().items()}
    counts.update({f"blignaut_{k}": v for k, v in b_features.counts().items()})
    failures = [f"guestrin {name} {f}" for name, g in runs.items() for f in g.failures]
    failures += [f"blignaut model {k} {c}: {why}" for (k, c), why in b.failures.items()]
    return {"profiles": {n: {"h1": g.h1, "h2": g.h2, "params": g.params} for n, g in runs.items()},
            "errors": b.errors, "failures": failures, "counts": counts}


def run_study(
    eyes: EyeModel,
    *,
    profile: str = "study-code",
    compare: str | None = "best",
    head_positions: str = "study-code",
    workers: int | None = None,
    scheduler: str | None = None,
    progress=None,
    guestrin_scene: Scene | None = None,
    blignaut_scene: Scene | None = None,
    batched: bool = True,
    chunk_eyes: int | None = None,
) -> StudyResult:
    """Both experiments on every eye with the Guestrin `profile` (and `compare` on the same features)."""
    if profile not in PROFILES or (compare is not None and compare not in PROFILES):
        raise ValueError(f"unknown Guestrin profile; known: {', '.join(PROFILES)}")
    if head_positions not in HEAD_POSITIONS:
        raise ValueError(f"unknown head positions {head_positions!r}; known: {', '.join(HEAD_POSITIONS)}")
    eyes = eyes.as_batch()
    g_scene = guestrin_scene or load_scene("guestrin2006")
    heads = HEAD_POSITIONS[head_positions]
    if heads is not None:
        g_scene = replace(g_scene, head_positions=heads)
    b_scene = blignaut_scene or load_scene("blignaut2014")
    size = chunk_eyes or (CHUNK_EYES if batched else 10)
    chunks = [eyes[a : a + size] for a in range(0, len(eyes), size)]
    profiles = (profile,) if compare in (None, profile) else (profile, compare)
    start = time.perf_counter()
    parts = run_chunks(run_chunk, chunks, sizes=[len(c) for c in chunks], workers=workers, scheduler=scheduler,
                       progress=progress, guestrin_scene=g_scene, blignaut_scene=b_scene, profiles=profiles,
                       batched=batched)
    counts: dict[str, int] = {}
    for part in parts:
        for k, v in part["counts"].items():
            counts[k] = counts.get(k, 0) + v
    failures = sorted({f for part in parts for f in part["failures"]})
    runs = {name: {k: np.concatenate([p["profiles"][name][k] for p in parts]) for k in ("h1", "h2", "params")}
            for name in profiles}
    return StudyResult(
        eyes=eyes, h1=runs[profile]["h1"], h2=runs[profile]["h2"], guestrin_params=runs[profile]["params"],
        blignaut_errors=np.concatenate([p["errors"] for p in parts]), failures=failures, counts=counts,
        settings={"guestrin_profile": profile, "compare_profile": compare,
                  "estimator_options": {n: asdict(PROFILES[n]) for n in profiles},
                  "head_positions": head_positions,
                  "head_offsets_mm": {h.name: [h.x, h.y, h.z] for h in g_scene.head_positions},
                  "guestrin_scene": g_scene.name, "blignaut_scene": b_scene.name,
                  "media": g_scene.media, "wavelength_nm": g_scene.wavelength_nm,
                  "seconds": time.perf_counter() - start, "configurations": list(CONFIGURATIONS),
                  "batched": batched, "chunk_eyes": size},
        profiles=runs,
    )
