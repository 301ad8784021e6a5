"""Ctrl-C during `eyehil study`: the process pool stops at once, exit 130, no traceback, no output that looks
complete. The pool and the output folder are tested on their own with explicit events (a worker blocked on a FIFO
nobody writes, a progress callback that raises); one end-to-end run interrupts the real command like a terminal
does (SIGINT to its process group) once its workers exist."""

from __future__ import annotations

import multiprocessing
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from leaks import process_running
from terminal import AS_FROM_A_TERMINAL

from eyehil.analysis.output_folder import staged_folder
from eyehil.parallel import run_chunks, worker_pool

GENEROUS_S = 120.0


def _blocked_unless_first(chunk: tuple[int, str]) -> int:
    """Chunk 0 returns at once; the others block reading a FIFO (until the test's watchdog writes to it)."""
    index, fifo = chunk
    if index:
        with open(fifo, "rb", buffering=0) as fh:
            fh.read(1)
    return index


def _interrupted_while_submitted(*, func, chunks: list, **_: object) -> None:
    """`worker_pool` (as `eyehil discrepancy` uses it): Ctrl-C once chunk 0 is back, the others still running."""
    with worker_pool(2) as pool:
        futures = [pool.submit(func, c) for c in chunks]
        futures[0].result()
        raise KeyboardInterrupt


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs a FIFO")
@pytest.mark.parametrize("run", [run_chunks, _interrupted_while_submitted])
def test_an_interrupt_terminates_the_workers_instead_of_waiting(tmp_path: Path, run) -> None:
    fifo = tmp_path / "never-written"
    os.mkfifo(fifo)
    released = threading.Event()
    finished = threading.Event()
    held: list[int] = []

    def watchdog() -> None:  # only if the pool waits for the blocked chunks (the bug): release them all
        if not finished.wait(GENEROUS_S):
            released.set()
            held.append(os.open(fifo, os.O_RDWR))  # open both ends, never blocks; readers then find a byte each
            os.write(held[0], b"x" * 64)

    threading.Thread(target=watchdog, daemon=True).start()

    def progress(n: int) -> None:
        raise KeyboardInterrupt  # Ctrl-C while the other chunks run and wait in the queue

    chunks = [(i, str(fifo)) for i in range(6)]
    try:
        with pytest.raises(KeyboardInterrupt):
            run(func=_blocked_unless_first, chunks=chunks, sizes=[1] * 6, workers=2, progress=progress)
    finally:
        finished.set()
        for fd in held:
            os.close(fd)
    assert not released.is_set(), "run_chunks waited for the running chunks"
    assert multiprocessing.active_children() == []


def test_staged_output_appears_only_when_complete(tmp_path: Path) -> None:
    out = tmp_path / "study"
    with pytest.raises(KeyboardInterrupt), staged_folder(out) as partial:
        (partial / "summary.json").write_text("{}")
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == []

    with staged_folder(out) as partial:
        (partial / "summary.json").write_text("new")
        (partial / "figs").mkdir()
        (partial / "figs" / "a.png").write_bytes(b"png")
        assert not out.exists()
    assert (out / "summary.json").read_text() == "new" and (out / "figs" / "a.png").read_bytes() == b"png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]


def test_a_failed_rerun_leaves_the_earlier_output_alone(tmp_path: Path) -> None:
    out = tmp_path / "study"
    out.mkdir()
    (out / "summary.json").write_text("earlier")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(RuntimeError), staged_folder(out) as partial:
        (partial / "summary.json").write_text("half")
        raise RuntimeError("crash while writing")
    assert (out / "summary.json").read_text() == "earlier"
    with staged_folder(out) as partial:
        (partial / "summary.json").write_text("later")
    assert (out / "summary.json").read_text() == "later" and (out / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]


def test_an_output_path_that_is_a_file_is_refused_before_the_work(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match="is not a folder"), staged_folder(tmp_path / "f"):
        pytest.fail("must not run")


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except (FileNotFoundError, ProcessLookupError):
        return []


@pytest.mark.skipif(not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").exists(), reason="needs Linux /proc")
def test_ctrl_c_stops_eyehil_study(tmp_path: Path) -> None:
    """61 eyes: two chunks (of `CHUNK_EYES` 50), so two worker processes; SIGINT once both exist and the
    progress bar is up, sent to the process group as a terminal's Ctrl-C is."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "eyehil", "study", "--eyes", "61", "--workers", "2", "--compare",
                             "none", "--out", str(out)], cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, **AS_FROM_A_TERMINAL)
    err = bytearray()

    def read() -> None:
        for chunk in iter(lambda: proc.stderr.read1(4096), b""):
            err.extend(chunk)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    deadline = time.monotonic() + GENEROUS_S
    workers: list[int] = []
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            workers = _children(proc.pid)
            if len(workers) >= 2 and re.search(rb"study:\s+\d+%", err):
                break
            threading.Event().wait(0.05)  # polling a condition, not a timing assumption
        assert len(workers) >= 2 and proc.poll() is None, err.decode(errors="replace")
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(GENEROUS_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    reader.join(GENEROUS_S)
    text = err.decode(errors="replace")
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text
    assert text.rstrip().splitlines()[-1].endswith("eyehil study: interrupted")
    assert not any(process_running(w) for w in workers)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # neither --out nor a partial folder
