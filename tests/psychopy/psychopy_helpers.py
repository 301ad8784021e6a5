"""Run a script under PsychoPy's own Python (its own virtual environment; `EYEHIL_PSYCHOPY_PYTHON`), headless
under Xvfb, reading its stdout line by line with a deadline."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

HERE = Path(__file__).parent
DEADLINE_S = 300.0  # ioHub starts a server process of its own; a busy machine takes minutes
SCREEN = "-screen 0 1920x1080x24"


def psychopy_python() -> str:
    """The PsychoPy environment's python, or skip the test saying why."""
    python = os.environ.get("EYEHIL_PSYCHOPY_PYTHON", "")
    if not python:
        pytest.skip("EYEHIL_PSYCHOPY_PYTHON is not set (the python of a venv with psychopy and the eye tracker "
                    "plugins; .ci/run makes one)")
    if not os.access(python, os.X_OK):
        pytest.skip(f"EYEHIL_PSYCHOPY_PYTHON={python} is not an executable")
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run is missing (Debian package xvfb): PsychoPy needs an X display")
    return python


class Script:
    """A running script: `line(prefix)` waits for its next stdout line starting with `prefix`; `send` writes a
    line to its stdin; every line read is kept in `lines`."""

    def __init__(self, name: str, *args: object) -> None:
        cmd = ["xvfb-run", "-a", "-s", SCREEN, psychopy_python(), str(HERE / name), *map(str, args)]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, cwd=HERE, start_new_session=True)  # its group: xvfb-run, X, python
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.end = time.monotonic() + DEADLINE_S

    def _read(self) -> None:
        for line in self.proc.stdout:
            self._queue.put(line.rstrip("\n"))
        self._queue.put(None)

    def line(self, prefix: str, within_s: float | None = None) -> str:
        """The rest of the next line that starts with `prefix`; `TimeoutError` if none comes within `within_s`
        (AssertionError at the script's deadline)."""
        end = self.end if within_s is None else min(self.end, time.monotonic() + within_s)
        while True:
            try:
                line = self._queue.get(timeout=max(0.1, end - time.monotonic()))
            except queue.Empty:
                if end < self.end:
                    raise TimeoutError(f"no {prefix!r} line within {within_s} s") from None
                raise AssertionError(f"no {prefix!r} line within {DEADLINE_S} s:\n" + self.tail()) from None
            if line is None:
                raise AssertionError(f"the script ended before a {prefix!r} line:\n" + self.tail())
            self.lines.append(line)
            if line.startswith(prefix):
                return line[len(prefix):].strip()

    def samples(self, after_s: float) -> list[dict]:
        """The ``SAMPLE <json>`` records read so far whose ``time`` is later than `after_s`."""
        records = (json.loads(line[len("SAMPLE"):]) for line in self.lines if line.startswith("SAMPLE"))
        return [r for r in records if r["time"] > after_s]

    def send(self, text: str) -> None:
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()

    def tail(self, n: int = 40) -> str:
        return "\n".join(self.lines[-n:])

    def close(self) -> None:
        """Wait for the end (or, at the deadline, kill its whole process group: the script under xvfb-run holds
        the pipe the reader reads), then join the reader."""
        try:
            self.proc.wait(timeout=max(1.0, self.end - time.monotonic()))
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self._reader.join(timeout=10)
        self.proc.stdin.close()
        self.proc.stdout.close()
