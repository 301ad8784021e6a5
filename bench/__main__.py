"""Run the benchmarks: `python -m bench` (all), `python -m bench forward study` (some), `--quick` (one repeat).

Each benchmark module has `run(repeats) -> dict` and `report(results) -> str` and prints one line (stdout); which
benchmark runs, and how long each took, goes to stderr.
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import sys
import time

BENCHMARKS = [
    "forward",
    "study",
    "render",
    "usbip",
    "device",
    "zmq",
    "frames",
    "view",  # the live web view in headless Chromium (bench/view.py)
    "opengaze",  # Gazepoint Open Gaze samples at 60 and 150 Hz (bench/opengaze.py)
    "discrepancy",  # the default eyehil discrepancy run (bench/discrepancy.py)
    "firmware",  # the firmware's C feature extractor (bench/firmware.py)
    "firmware_stream",  # the C firmware streaming 500 Hz in real time: exposures lost (bench/firmware_stream.py)
]
ON_REQUEST = ["fuzz", "soak", "faults", "stimulus"]  # long runs, and the STIMULUS ACK latency alone


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    parser.add_argument("names", nargs="*", help=f"benchmarks to run (default all: {', '.join(BENCHMARKS)})")
    parser.add_argument("--quick", action="store_true", help="one repeat instead of three")
    parser.add_argument("--eyes", type=int, default=None,
                        help="study only: the study on this many Rozema eyes, local and on Dask (bench/study_scale.py)")
    args = parser.parse_args()
    unknown = set(args.names) - set(BENCHMARKS) - set(ON_REQUEST)
    if unknown:
        parser.error(f"unknown benchmark(s) {', '.join(sorted(unknown))}; known: {', '.join(BENCHMARKS + ON_REQUEST)}")
    repeats = 1 if args.quick else 3
    print(f"# {platform.python_implementation()} {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"{platform.machine()}; best of {repeats}")
    if args.eyes is not None and (args.eyes < 1 or set(args.names) != {"study"}):
        parser.error("--eyes goes with the study benchmark alone: python -m bench study --eyes 10000")
    names = args.names or BENCHMARKS
    for i, name in enumerate(names, start=1):
        start = time.perf_counter()
        print(f"[{i}/{len(names)}] {name} ...", file=sys.stderr, flush=True)  # progress: the results go to stdout
        if args.eyes is not None:
            module = importlib.import_module("bench.study_scale")
            print(module.report(module.run(repeats, eyes=args.eyes)), flush=True)
        else:
            module = importlib.import_module(f"bench.{name}")
            print(module.report(module.run(repeats)), flush=True)
        print(f"[{i}/{len(names)}] {name} took {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
