"""Benchmark: the firmware's C feature extractor (`firmware_stubs/extract.c`, built -O2 by ``make lib``) on one
core: frames per second for a 320x240 region of interest and a full 640x480 frame.

Frames: published eyes x 9 targets of the Guestrin 2006 scene (central head position; 20 eyes for regions, 5 for
full frames), rendered beforehand by the project's renderer with its default blur and noise (not timed); each
frame is extracted `LOOPS` times in one C call (`ex_extract_flat`'s repeat count, so Python's call overhead is
not timed), two LEDs lit. Time is the process's CPU time (`time.process_time`: the extractor is single-threaded,
so this is one core's time, and it does not count the waits of a shared machine). Also shown, not targeted: the
1600x1200 full frame of the Blignaut 2014 scene (both eyes, 1 published eye x 9 targets). Targets (issue 12):
>= 1,000 region frames/s and >= 250 full frames/s.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate
from eyehil.emulator.render.geometry import eye_outlines
from eyehil.emulator.render.renderer import render_full, render_roi
from eyehil.emulator.scene import load_scene
from firmware_stubs.extractor import Extractor, build_library

TARGETS = {"roi_fps": 1000.0, "full_fps": 250.0}
LOOPS = 20


def _frames(scene_name: str, n_eyes: int, roi: bool) -> list:
    scene = load_scene(scene_name)
    eyes = published_eyes()[:n_eyes]
    outline = eye_outlines(simulate(eyes, scene, head_positions=scene.head_positions[:1]), eyes, scene)
    rng = np.random.default_rng(0)
    if roi:
        return [render_roi(outline[e, 0, 0, t], rng).image for e in range(outline.shape[0])
                for t in range(outline.shape[3])]
    return [render_full(outline[e, :, 0, t], rng).image for e in range(outline.shape[0])
            for t in range(outline.shape[3])]


def run(repeats: int = 3) -> dict[str, float]:
    """Best-of-`repeats` frames per second of each kind of frame."""
    with tempfile.TemporaryDirectory(prefix="eyehil-bench-") as build:
        extractor = Extractor(build_library(Path(build)))
        led_dir = np.array([[1.0, 0.0], [-1.0, 0.0]])
        sets = {
            "roi_fps": (_frames("guestrin2006", 20, roi=True), 1),
            "full_fps": (_frames("guestrin2006", 5, roi=False), 1),
            "full_1600_fps": (_frames("blignaut2014", 1, roi=False), 2),
        }
        results = {}
        for name, (frames, eyes) in sets.items():
            def stage(frames=frames, eyes=eyes) -> None:
                for image in frames:
                    extractor.extract(image, lit_mask=0b11 if eyes == 1 else 0b01, max_eyes=eyes,
                                      led_dir=led_dir, repeats=LOOPS)
            results[name] = len(sets[name][0]) * LOOPS / _best(stage, repeats)
            results[f"{name}_frames"] = len(frames)
    return results


def _best(stage, repeats: int) -> float:
    """Shortest CPU time (s) of `repeats` runs of `stage` after one warm-up run."""
    stage()
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        stage()
        best = min(best, time.process_time() - start)
    return best


def report(results: dict[str, float]) -> str:
    parts = []
    for name, label in (("roi_fps", "320x240 region"), ("full_fps", "640x480 frame")):
        verdict = "PASS" if results[name] >= TARGETS[name] else "FAIL"
        parts.append(f"{label} {results[name]:,.0f}/s = {1e6 / results[name]:.0f} us/frame "
                     f"(target >= {TARGETS[name]:,.0f}: {verdict})")
    parts.append(f"1600x1200 binocular frame {results['full_1600_fps']:,.0f}/s (no target)")
    return (f"firmware extractor (C, one core, {results['roi_fps_frames']:.0f} frames x {LOOPS} each): "
            + "; ".join(parts))
