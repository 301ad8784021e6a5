"""`eyehil`: one console command; each subcommand lives in the package it belongs to.

The table maps a subcommand to "module:function"; the module is imported only when that subcommand
runs, and its function `register(subparsers)` adds the parser and sets `func`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS: dict[str, str] = {
    "simulate": "eyehil.emulator.simulate:register",
    "emulate": "eyehil.emulator.device.cli:register",
    "info": "eyehil.drivers.cli:register_info",
    "stream": "eyehil.drivers.cli:register_stream",
    "calibrate": "eyehil.drivers.cli:register_calibrate",
    "record": "eyehil.drivers.cli:register_record",
    "render": "eyehil.emulator.render.cli:register",
    "study": "eyehil.analysis.study.cli:register",
    "discrepancy": "eyehil.analysis.discrepancy.cli:register",
}


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eyehil", description="Hardware-in-the-loop remote eye-tracker emulator.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    wanted = next((a for a in argv if not a.startswith("-")), None)
    for name, target in COMMANDS.items():
        if wanted in (None, name) or wanted not in COMMANDS:
            module, func = target.split(":")
            getattr(importlib.import_module(module), func)(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as exc:
        print(f"eyehil {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
