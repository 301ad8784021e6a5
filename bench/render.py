"""Benchmark: synthetic IR frames and host-side detection, on one core (`cv2.setNumThreads(1)`).

Frames of 20 published eyes x 9 targets of the Guestrin 2006 scene (central head position; the geometry,
`render_geometry.eye_outlines`, is computed once beforehand and not timed): a 320x240 region of interest
rendered (its ground truth, `Frame.truth`, is computed when first asked for, as a streaming device never does;
also timed with it), the full 640x480 frame rendered, and the region detected (`eyehil.drivers.detect`).
Targets (issue "Synthetic infrared frames"): >= 1,000 region frames/s and >= 300 full frames/s rendered,
>= 500 region frames/s detected.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from eyehil.drivers.detect import detect_eye
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import simulate
from eyehil.emulator.render.geometry import eye_outlines
from eyehil.emulator.render.renderer import render_full, render_roi
from eyehil.emulator.scene import load_scene

TARGETS = {"roi_render_fps": 1000.0, "full_render_fps": 300.0, "roi_detect_fps": 500.0}


def run(repeats: int = 3) -> dict[str, float]:
    """Best-of-`repeats` frames per second of each stage."""
    scene = load_scene("guestrin2006")
    eyes = published_eyes()[:20]
    outline = eye_outlines(simulate(eyes, scene, head_positions=scene.head_positions[:1]), eyes, scene)
    samples = [outline[e, 0, 0, t] for e in range(outline.shape[0]) for t in range(outline.shape[3])]
    leds = scene.leds[:, :2]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        rng = np.random.default_rng(0)
        frames = [render_roi(s, rng) for s in samples]
        stages = {
            "roi_render_fps": lambda: [render_roi(s, rng) for s in samples],
            "roi_truth_fps": lambda: [render_roi(s, rng).truth for s in samples],
            "full_render_fps": lambda: [render_full(s, rng) for s in samples],
            "roi_detect_fps": lambda: [detect_eye(f.image, 2, roi_xy=f.roi_xy, led_xy_mm=leds) for f in frames],
        }
        results = {name: len(samples) / _best(stage, repeats) for name, stage in stages.items()}
    finally:
        cv2.setNumThreads(threads)
    results["frames"] = len(samples)
    return results


def _best(stage, repeats: int) -> float:
    """Shortest wall time (s) of `repeats` runs of `stage` after one warm-up run."""
    stage()
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        stage()
        best = min(best, time.perf_counter() - start)
    return best


def report(results: dict[str, float]) -> str:
    parts = []
    for name, label in (("roi_render_fps", "render 320x240 region"), ("full_render_fps", "render 640x480 frame"),
                        ("roi_detect_fps", "detect 320x240 region")):
        verdict = "PASS" if results[name] >= TARGETS[name] else "FAIL"
        parts.append(f"{label} {results[name]:,.0f}/s (target >= {TARGETS[name]:,.0f}: {verdict})")
    parts.insert(1, f"the region with its ground truth {results['roi_truth_fps']:,.0f}/s")
    return f"frames, one core, {results['frames']:.0f} frames each: " + "; ".join(parts)
