"""STIMULUS ACK latency while streaming, alone: `python -m bench stimulus` (the first part of `bench soak`).

The device (real clock, 1 kHz FEATURES, its own process on a pty) gets `STIMULI` (default 200) STIMULUS
commands, each at a new position so that each starts a fixation solve; the host measures each round trip. Runs:
the solves in a worker process (the device's default on the real clock, `solve_process`), the same with
the solves on a thread of the device's process (as before issue 11's fix), and the control: every STIMULUS at
one position (no solve at all), so the differences are what the solves cost the device's thread. Target
(issue 11): p99 <= 10 ms. Environment: STIMULI; STIMULUS_RUNS (default "process,thread,control").
"""

from __future__ import annotations

import os

from bench.soak import stimulus_latency

RUNS = {"process": {"solves": "process"}, "thread": {"solves": "thread"},
        "control": {"solves": "process", "new_positions": False}}
LABELS = {"process": "new positions, solves in a worker process", "thread": "new positions, solves on a thread",
          "control": "one position (control, no solve)"}


def run(repeats: int) -> dict:
    """Each run once (a run is already `STIMULI` round trips); the 1-minute load average after each."""
    count = int(os.environ.get("STIMULI", "200"))
    out = {}
    for name in os.environ.get("STIMULUS_RUNS", "process,thread,control").split(","):
        out[name] = stimulus_latency(count, **RUNS[name]) | {"load": os.getloadavg()[0]}
    return out


def report(results: dict) -> str:
    """One line per run."""
    return "\n".join(
        f"stimulus ACK, {r['stimuli']} STIMULUS while streaming 1 kHz on a pty, {LABELS[name]}: p50 {r['p50_ms']:.2f} "
        f"ms, p99 {r['p99_ms']:.2f} ms, max {r['max_ms']:.2f} ms, {r['retries']} retries, {r['unanswered']} unanswered "
        f"(load {r['load']:.1f})" for name, r in results.items())
