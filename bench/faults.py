"""The fault-injecting link at scale: `python -m bench faults` (issue 11's 60 s run).

The test suite's run (tests/device/test_reliability_faults.py, 6 s) at `FAULT_S` seconds (default 60) of
1 kHz features on the loop device's fast clock in lockstep with the host: drop, duplicate, corrupt, delay
and reorder at 0.5 % each, plus one disconnect in the middle with a 100-frame outage. The run is judged by
the test module's own checks (the same functions, called on the long run's result): every kind of fault
happened, the host's loss count equals the truth exactly, no damaged or duplicated sample reaches the
application, and the recording marks every gap.

Environment: FAULT_S (seconds of samples at 1 kHz), FAULT_SEED.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

from eyehil.drivers.links.fault import FaultSpec
from eyehil.drivers.recording import read_recording

TESTS = Path(__file__).resolve().parent.parent / "tests" / "device"
CHECKS = ("test_every_kind_of_fault_happened", "test_no_damaged_or_duplicated_sample_reaches_the_application",
          "test_host_loss_count_equals_the_truth", "test_recording_marks_every_gap")


def run(repeats: int) -> dict:
    """One long run (repeats do not apply: the run is judged, not timed)."""
    sys.path.insert(0, str(TESTS))
    import test_reliability_faults as checks  # the suite's harness and checks, not a copy

    samples = round(float(os.environ.get("FAULT_S", "60")) * 1000)
    spec = FaultSpec(drop=0.005, duplicate=0.005, corrupt=0.005, reorder=0.005, delay_p=0.005, delay_s=0.005,
                     after=20, disconnect=samples // 2, outage=100, seed=int(os.environ.get("FAULT_SEED", "7")))
    start = time.process_time()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.jsonl"
        result = checks.run_faulty_stream(samples, spec, path)
        result["recording"] = read_recording(path)
        verdicts = {}
        for name in CHECKS:
            try:
                getattr(checks, name)(result)
                verdicts[name] = "held"
            except AssertionError as exc:
                verdicts[name] = f"FAILED: {str(exc).splitlines()[0]}"
    log, stats = result["log"], result["stats"]
    return {"samples": samples, "frames": log.frames, "cpu_s": time.process_time() - start, "verdicts": verdicts,
            "faults": {k: len(getattr(log, k)) for k in ("dropped", "duplicated", "corrupted", "delayed",
                                                          "reordered", "outage")},
            "lost_frames": stats.lost_frames, "crc_errors": stats.crc_errors,
            "duplicates_dropped": stats.duplicates_dropped, "reconnects": result["reconnects"]}


def report(results: dict) -> str:
    ok = all(v == "held" for v in results["verdicts"].values())
    faults = ", ".join(f"{k} {v}" for k, v in results["faults"].items())
    lines = [f"faults: {results['samples']:,} samples at 1 kHz ({results['samples'] / 1000:.0f} s simulated, "
             f"{results['cpu_s']:.0f} s CPU); injected into {results['frames']:,} frames: {faults}; "
             f"host: lost {results['lost_frames']}, "
             f"CRC errors {results['crc_errors']}, duplicates dropped {results['duplicates_dropped']}, "
             f"reconnects {results['reconnects']} -> {'PASS' if ok else 'FAIL'}"]
    lines += [f"  {name.removeprefix('test_').replace('_', ' ')}: {verdict}"
              for name, verdict in results["verdicts"].items()]
    return "\n".join(lines)
