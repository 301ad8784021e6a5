"""Run every benchmark: `python -m bench` (add `--quick` for one repeat). Prints one line per benchmark."""

from __future__ import annotations

import argparse
import os
import platform

from bench import forward


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="one repeat instead of three")
    args = parser.parse_args()
    repeats = 1 if args.quick else 3
    print(f"# {platform.python_implementation()} {platform.python_version()}, {os.cpu_count()} CPUs, "
          f"{platform.machine()}; best of {repeats}")
    results = forward.run(repeats)
    print(forward.report(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
