"""Exact fixation solves in a worker process, so that they never hold the device process's GIL.

`ProcessSolves` is the `solver.SolveBackend` of a device on the real clock. A solve (`FeatureSolver.solve`, one
forward-model call, 10-300 ms of pure Python and numpy) run on a thread of the device's process holds the GIL
most of that time, and the device's streaming thread waits for it between samples: STIMULUS ACKs measured
p99 299 ms while solves ran (issue 11). Here the solve runs in one worker process ("eyehil-solver", the
multiprocessing "spawn" context: a fresh interpreter, no copy of the device's threads or locks), and the
calling thread only waits on a pipe, without the GIL.

- The solver (anatomy, scene, head pose, settings: a few kB; `FeatureSolver.__getstate__`, without its cache
  or grid) is pickled once, when the process starts; a request is then just the points (N, 2) screen mm and
  the reply the features (N, E, C).
- One request at a time: `solve` is called by `SolveQueue`'s single worker thread, which already coalesces
  the requests, so the pipe never holds more than one request and the stop message.
- The process starts on the first `solve` (on the calling thread, never the device's); if it dies (killed,
  out of memory), the next `solve` starts a new one, `MAX_STARTS` times in all, then every solve fails (the
  subject interpolates, as it does for any failed solve). An exception inside the worker's solve comes back as
  `SolveProcessError` with the worker's traceback; the worker goes on.
- No orphans: `close` sends a stop, waits `STOP_GRACE_S`, then terminates (and kills) the worker. The worker
  ignores SIGINT (a terminal's Ctrl-C reaches the whole process group: the device stops it, cleanly), is a
  daemon process (multiprocessing terminates it when the device's interpreter exits), and exits by itself
  when its pipe closes or its parent changes (the device killed with SIGKILL), checked every
  `PARENT_CHECK_S`.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import traceback
from multiprocessing.connection import Connection, wait

import numpy as np

from eyehil.emulator.device.solver import FeatureSolver

MAX_STARTS = 3  # worker processes started in the life of one backend (the first and two replacements)
STOP_GRACE_S = 1.0  # how long `close` lets the worker finish before terminating it
PARENT_CHECK_S = 1.0  # how often an idle worker checks that its device is still there


class SolveProcessError(RuntimeError):
    """A solve failed in the worker process (its traceback is the message), or the worker is gone."""


class ProcessSolves:
    """A `SolveBackend` whose solves run in one worker process; see the module docstring.

    Counters: ``starts`` (worker processes started), ``requests`` (solves sent to the worker).
    """

    def __init__(self, solver: FeatureSolver, *, context: str = "spawn") -> None:
        """Nothing starts yet: the worker process starts on the first `solve`."""
        self.solver = solver
        self._context = multiprocessing.get_context(context)
        self._process: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._solve_lock = threading.Lock()  # one request in flight
        self._send_lock = threading.Lock()  # `close` may send the stop while a solve waits for its reply
        self._closed = False
        self.starts = self.requests = 0

    @property
    def pid(self) -> int | None:
        """The worker's process id while it runs, else None."""
        process = self._process
        return process.pid if process is not None and process.is_alive() else None

    def solve(self, xy: np.ndarray) -> np.ndarray:
        """Exact features (N, E, C) of points (N, 2) screen mm, computed by the worker; blocks (without the GIL)
        until it answers. Raises `SolveProcessError` if the worker's solve raised or the worker is gone."""
        with self._solve_lock:
            conn, process = self._ensure_started()
            try:
                with self._send_lock:
                    conn.send(np.ascontiguousarray(xy, dtype=float).reshape(-1, 2))
                self.requests += 1
                wait([conn, process.sentinel])
                if not conn.poll():  # the worker died without an answer
                    raise SolveProcessError(f"solver process {process.pid} exited ({process.exitcode})")
                kind, value = conn.recv()
            except (EOFError, OSError) as exc:
                raise SolveProcessError(f"solver process {process.pid} is gone: {exc!r}") from exc
        if kind != "ok":
            raise SolveProcessError(value)
        return value

    def _ensure_started(self) -> tuple[Connection, multiprocessing.process.BaseProcess]:
        """The running worker and its pipe; starts one if there is none (called with `_solve_lock` held)."""
        if self._closed:
            raise SolveProcessError("solver process closed")
        if self._process is not None and self._process.is_alive() and self._conn is not None:
            return self._conn, self._process
        self._reap()
        if self.starts >= MAX_STARTS:
            raise SolveProcessError(f"solver process failed {self.starts} times; not restarted")
        here, there = self._context.Pipe(duplex=True)
        process = self._context.Process(target=serve, args=(there, self.solver, os.getpid()),
                                        name="eyehil-solver", daemon=True)
        # Started with SIGINT blocked, so that a Ctrl-C while the worker still imports cannot reach it (a new
        # process inherits the mask; `serve` ignores SIGINT, then unblocks it). Only this thread's mask changes.
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
        there.close()
        self.starts += 1
        with self._send_lock:
            self._process, self._conn = process, here
        if self._closed:  # closed while starting: `close` did not see this process
            self._stop(process, here)
            raise SolveProcessError("solver process closed")
        return here, process

    def _reap(self) -> None:
        """Forget a worker that died (collect its exit status, close its pipe)."""
        if self._process is not None:
            self._process.join(0)
        if self._conn is not None:
            self._conn.close()
        self._process = self._conn = None

    def close(self) -> None:
        """Stop the worker: a stop message, `STOP_GRACE_S` to obey, then terminate and kill; idempotent."""
        with self._send_lock:
            self._closed = True
            process, conn = self._process, self._conn
        if process is not None and conn is not None:
            self._stop(process, conn)
        with self._solve_lock:  # a solve that waited on the worker has returned (its process is dead)
            self._reap()

    def _stop(self, process: multiprocessing.process.BaseProcess, conn: Connection) -> None:
        with self._send_lock, contextlib.suppress(OSError, ValueError):
            conn.send(None)
        process.join(STOP_GRACE_S)
        if process.is_alive():
            process.terminate()
            process.join(STOP_GRACE_S)
        if process.is_alive():
            process.kill()
            process.join()


def serve(conn: Connection, solver: FeatureSolver, parent_pid: int) -> None:
    """The worker process: answer each request (points (N, 2)) with ("ok", features) or ("error", traceback)
    until a None request, a closed pipe or a new parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is for the device, which stops us
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    while True:
        try:
            if not conn.poll(PARENT_CHECK_S):
                if os.getppid() != parent_pid:
                    return  # the device died without closing us
                continue
            request = conn.recv()
        except (EOFError, OSError):
            return
        if request is None:
            return
        try:
            reply = ("ok", solver.solve(request))
        except Exception:  # reported to the device, which logs it; the next request may well succeed
            reply = ("error", traceback.format_exc())
        try:
            conn.send(reply)
        except OSError:
            return
