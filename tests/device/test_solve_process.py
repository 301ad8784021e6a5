"""Fixation solves in a worker process (`solve_process.ProcessSolves`, issue 11): same answers, the solver sent
once, failures contained, the device answering from the grid while the worker holds the exact solve, and no
worker left behind when the device closes, is killed, or gets a Ctrl-C.

The worker's timing is controlled by a file (`solve_helpers.HeldSolver`: a fixation solve waits until the file
exists), not by the clock; waits on real processes have generous deadlines that only bound a hang.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from leaks import process_running
from solve_helpers import FAILING_X, GENEROUS_S, HeldSolver, closed_form
from terminal import AS_FROM_A_TERMINAL
from waiting import wait_until

from eyehil.drivers.client import open_tracker
from eyehil.emulator.device import solve_process
from eyehil.emulator.device.solve_process import ProcessSolves, SolveProcessError
from eyehil.emulator.device.solver import FeatureSolver
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.scene import load_scene

HERE = Path(__file__).resolve().parent


def _until(condition, what: str) -> None:
    """Wait (generously) for a condition about a real process."""
    wait_until(condition, what, GENEROUS_S)


def _solve_workers(parent: int) -> list[int]:
    """Running solve workers whose parent is `parent`."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                cmdline = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if int(stat[1]) == parent and stat[0] != "Z" and solve_process.BOOT.encode() in cmdline:
                found.append(int(entry.name))
    return found


@pytest.fixture
def released(tmp_path) -> HeldSolver:
    """A HeldSolver that never holds."""
    (tmp_path / "release").touch()
    return HeldSolver(tmp_path / "release")


def test_worker_solves_exactly_as_the_solver_and_gets_it_once(monkeypatch) -> None:
    solver = FeatureSolver(normative_eye("navarro"), load_scene("guestrin2006"))
    pickled = []
    original = FeatureSolver.__getstate__
    monkeypatch.setattr(FeatureSolver, "__getstate__", lambda self: pickled.append(1) or original(self))
    backend = ProcessSolves(solver)
    try:
        points = [np.array([[10.0, 20.0]]), np.array([[-60.0, 35.0], [100.0, -80.0]]), np.array([[0.0, 0.0]])]
        answers, pids = [], set()
        for xy in points:
            answers.append(backend.solve(xy))
            pids.add(backend.pid)
        assert len(pids) == 1 and None not in pids and backend.starts == 1 and backend.requests == 3
        mine, worker = os.getpriority(os.PRIO_PROCESS, 0), os.getpriority(os.PRIO_PROCESS, backend.pid)
        assert worker == min(19, mine + solve_process.NICE)  # it yields the CPU to the device
        assert len(os.listdir(f"/proc/{backend.pid}/task")) == 1  # no thread pool keeping the default priority
        assert len(pickled) == 1  # the solver went to the worker once, with the process; requests are points
        monkeypatch.setattr(FeatureSolver, "__getstate__", original)
        for xy, answer in zip(points, answers, strict=True):
            np.testing.assert_array_equal(answer, solver.solve(xy))
        pid = backend.pid
    finally:
        backend.close()
    assert backend.pid is None and not process_running(pid)


def test_an_error_in_the_worker_comes_back_and_the_worker_goes_on(released: HeldSolver) -> None:
    backend = ProcessSolves(released)
    try:
        backend.solve(np.array([[1.0, 2.0]]))
        pid = backend.pid
        with pytest.raises(SolveProcessError, match="ValueError: bad point"):
            backend.solve(np.array([[FAILING_X, 2.0]]))
        np.testing.assert_array_equal(backend.solve(np.array([[3.0, 4.0]])),
                                      closed_form([[3.0, 4.0]], released.n_eyes, released.n_channels))
        assert backend.pid == pid and backend.starts == 1
    finally:
        backend.close()


def test_a_dead_worker_is_replaced_at_most_twice(released: HeldSolver) -> None:
    backend = ProcessSolves(released)
    try:
        for starts in range(1, solve_process.MAX_STARTS + 1):
            backend.solve(np.array([[1.0, 2.0]]))
            assert backend.starts == starts
            worker = backend._popen
            os.kill(worker.pid, signal.SIGKILL)
            worker.wait(GENEROUS_S)
        with pytest.raises(SolveProcessError, match="not restarted"):
            backend.solve(np.array([[1.0, 2.0]]))
    finally:
        backend.close()


def test_close_abandons_a_held_solve_and_leaves_no_worker(tmp_path) -> None:
    backend = ProcessSolves(HeldSolver(tmp_path / "release"))  # never released
    outcome: list[BaseException | np.ndarray] = []

    def solve() -> None:
        try:
            outcome.append(backend.solve(np.array([[5.0, 5.0]])))
        except BaseException as exc:  # recorded for the assertion
            outcome.append(exc)

    caller = threading.Thread(target=solve, daemon=True)
    caller.start()
    _until(lambda: backend.requests == 1, "the request to reach the worker")
    pid = backend.pid
    backend.close()
    caller.join(GENEROUS_S)
    assert not caller.is_alive() and isinstance(outcome[0], SolveProcessError)
    assert not process_running(pid) and backend.pid is None
    with pytest.raises(SolveProcessError, match="closed"):
        backend.solve(np.array([[5.0, 5.0]]))
    backend.close()  # idempotent


def test_subject_answers_from_the_grid_while_the_worker_holds_the_exact_solve(tmp_path) -> None:
    release = tmp_path / "release"
    release.touch()
    solver = HeldSolver(release)
    subject = Subject(solver, solves=ProcessSolves)  # start point and grid solved here, at construction
    release.unlink()
    try:
        subject.look_at((50.0, -30.0), 0)
        backend = subject._solves.backend
        assert isinstance(backend, ProcessSolves)
        _until(lambda: backend.requests == 1, "the fixation solve to reach the worker")  # and held there
        times = np.arange(1_000_000, 1_010_000, 1_000, dtype=np.int64)  # long after the saccade
        held = subject.observe(times)
        grid = solver.field(np.array([[50.0, -30.0]]))[0]
        np.testing.assert_allclose(held.values[0], grid)
        assert subject.interpolated_holds == len(times)
        release.touch()
        assert subject._solves.wait((50.0, -30.0), GENEROUS_S)
        exact = subject.observe(times + 10_000).values
        np.testing.assert_array_equal(exact[0], closed_form([[50.0, -30.0]], solver.n_eyes, solver.n_channels)[0])
        assert not np.allclose(exact[0], grid) and subject._solves.solved == 1
        pid = backend.pid
    finally:
        subject.close()
    assert not process_running(pid)


WORKER_SCRIPT = """
import sys
sys.path.insert(0, sys.argv[1])
import numpy as np
from solve_helpers import HeldSolver
from eyehil.emulator.device.solve_process import ProcessSolves
backend = ProcessSolves(HeldSolver(sys.argv[2]))
backend.solve(np.array([[1.0, 2.0]]))
print(backend.pid, flush=True)
sys.stdin.read()
"""


def test_a_killed_device_leaves_no_worker(released: HeldSolver) -> None:
    proc = subprocess.Popen([sys.executable, "-c", WORKER_SCRIPT, str(HERE), released.release],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        worker = int(proc.stdout.readline())
        assert process_running(worker)
        proc.kill()  # SIGKILL: no atexit, no close
        proc.wait(GENEROUS_S)
        _until(lambda: not process_running(worker), "the orphaned worker to exit")
    finally:
        proc.kill()
        proc.wait(GENEROUS_S)


def test_ctrl_c_stops_the_emulator_and_its_worker() -> None:
    """`eyehil emulate` on the real clock gets a STIMULUS (its worker starts), then a terminal's Ctrl-C (SIGINT
    to the whole process group): it exits 130 (issue 17), its worker is gone, and nothing printed a traceback."""
    proc = subprocess.Popen([sys.executable, "-m", "eyehil", "emulate", "--link", "tcp", "--duration", "300"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **AS_FROM_A_TERMINAL)
    workers: list[int] = []
    tracker = None
    try:
        url = proc.stdout.readline().strip().removeprefix("url: ")
        tracker = open_tracker(url, timeout=GENEROUS_S, response_timeout=GENEROUS_S)
        tracker.stimulus(1, 30.0, 40.0)
        _until(lambda: bool(workers.extend(_solve_workers(proc.pid)) or workers), "the solve worker")
        os.killpg(proc.pid, signal.SIGINT)
        assert proc.wait(GENEROUS_S) == 130
        _, err = proc.communicate(timeout=GENEROUS_S)
        assert "Traceback" not in err, err
        _until(lambda: not any(process_running(w) for w in workers), "the worker to exit")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(GENEROUS_S)
        if tracker is not None:
            with contextlib.suppress(Exception):  # its device is gone
                tracker.wire.link.close()
