"""`eyehil`: one console command; each subcommand lives in the package it belongs to.

The table maps a subcommand to "module:function" and a one-line summary; the module is imported only when
that subcommand runs (or prints its own help), so `eyehil --help` and `eyehil --version` import nothing heavy.
The function `register(subparsers)` adds the subcommand's parser and sets `func`.

Errors end the command with one line on stderr: exit 2 for bad input (ValueError, a missing file), 1 for a
runtime error (an OSError such as a port in use, or an eyehil, ZeroMQ or pyserial exception), 130 for Ctrl-C.
Run as a command (`argv` None), Ctrl-C also freezes the heap (`gc.freeze`): the process is about to exit, and
the interpreter's final collections over numpy, scipy, pandas and matplotlib took about 1 s of CPU (3 s on a
busy machine) after the command had stopped.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": ("eyehil.emulator.simulate:register", "the forward model alone: ray-traced features and a summary"),
    "emulate": ("eyehil.emulator.device.cli:register", "run a virtual eye tracker on a link until interrupted"),
    "info": ("eyehil.drivers.cli:register_info", "host: print a tracker's device information"),
    "stream": ("eyehil.drivers.cli:register_stream", "host: print live samples (or frames detected with OpenCV)"),
    "calibrate": ("eyehil.drivers.cli:register_calibrate", "host: calibrate gaze through the device, then stream gaze"),
    "record": ("eyehil.drivers.cli:register_record", "host: record samples to a file"),
    "render": ("eyehil.emulator.render.cli:register", "write synthetic infrared frames with their ground truth"),
    "study": ("eyehil.analysis.study.cli:register", "the replication of Fischer et al. 2023 (the main job)"),
    "discrepancy": ("eyehil.analysis.discrepancy.cli:register", "find, name and add what the model misses"),
    "view": ("eyehil.drivers.view.cli:register", "host: a live web page of a tracker (camera, features, gaze, health)"),
}


def _start_view(*args, **kwargs):
    from eyehil.emulate_view import start_view

    return start_view(*args, **kwargs)


def _version() -> str:
    from eyehil import __version__

    return f"eyehil {__version__}"


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eyehil", description="Hardware-in-the-loop remote eye-tracker emulator.")
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    wanted = next((a for a in argv if not a.startswith("-")), None)
    for name, (target, summary) in COMMANDS.items():
        if name == wanted:
            module, func = target.split(":")
            getattr(importlib.import_module(module), func)(sub)
            if name == "emulate":  # the device does not import the host: its --view is joined here
                sub.choices[name].set_defaults(view_starter=_start_view)
        else:
            sub.add_parser(name, help=summary)
    return parser


def main(argv: list[str] | None = None) -> int:
    exits = argv is None  # the command line: the process ends when this returns
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"eyehil {args.command}: interrupted", file=sys.stderr)
        if exits:
            gc.freeze()
        return 130
    except (ValueError, FileNotFoundError) as exc:  # bad input: a usage error
        print(f"eyehil {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:
        if not _expected(exc):
            raise
        print(f"eyehil {args.command}: error: {exc}", file=sys.stderr)
        return 1


def _expected(exc: BaseException) -> bool:
    """An error the user can act on: the system's (a port in use, a refused connection) or eyehil's own."""
    return isinstance(exc, OSError) or type(exc).__module__.split(".")[0] in ("eyehil", "zmq", "serial")


if __name__ == "__main__":
    raise SystemExit(main())
