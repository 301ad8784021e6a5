"""Exact fixation solves in a worker process, so that they never hold the device process's GIL.

`ProcessSolves` is the `solver.SolveBackend` of a device on the real clock. A solve (`FeatureSolver.solve`, one
forward-model call, 10-300 ms of pure Python and numpy) run on a thread of the device's process holds the GIL
most of that time, and the device's streaming thread waits for it between samples: STIMULUS ACKs measured
p99 299 ms while solves ran (issue 11). Here the solve runs in one worker process (`python -c BOOT`, which
calls `main` here: a fresh interpreter, no copy of the device's threads or locks), and the
calling thread only waits on a pipe, without the GIL.

- The worker is a plain subprocess talking `multiprocessing.connection` messages over its stdin and stdout
  (rather than a multiprocessing "spawn" process, which would also start multiprocessing's resource tracker
  process for the device's lifetime and re-import the device's main script). The worker gets the device's
  `sys.path` (as PYTHONPATH: it imports what the device imports), and the pickled solver (anatomy, scene, head
  pose, settings: a few kB; `FeatureSolver.__getstate__`, without its cache or grid) once, when it starts;
  a request is then just the points (N, 2) screen mm, the reply ("ok", features (N, E, C)) or ("error",
  the worker's traceback).
- The worker is one thread (`ONE_THREAD`: no BLAS thread pool, whose threads would keep the default
  priority) and lowers its own priority (`NICE`): on a machine with fewer free cores than runnable processes
  it would otherwise take its CPU share from the device's streaming thread, as the thread did with the GIL;
  the exact solve then takes longer, and the subject interpolates meanwhile.
- One request at a time: `solve` is called by `SolveQueue`'s single worker thread, which already coalesces
  the requests, so the pipe never holds more than one request and the stop message.
- The worker starts on the first `solve` (on the calling thread, never the device's); if it dies (killed,
  out of memory), the next `solve` starts a new one, `MAX_STARTS` times in all, then every solve fails (the
  subject interpolates, as it does for any failed solve). An exception inside the worker's solve comes back as
  `SolveProcessError` with the worker's traceback; the worker goes on.
- No orphans: `close` sends a stop, waits `STOP_GRACE_S`, then terminates (and kills) the worker. The worker
  runs in its own session, so a terminal's Ctrl-C (SIGINT to the foreground process group) reaches only the
  device, which closes it; and it exits by itself when its pipe closes or its parent changes (the device
  killed with SIGKILL), checked every `PARENT_CHECK_S`.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import subprocess
import sys
import threading
import traceback
from multiprocessing.connection import Connection

import numpy as np

from eyehil.emulator.device.solver import FeatureSolver

MAX_STARTS = 3  # worker processes started in the life of one backend (the first and two replacements)
STOP_GRACE_S = 1.0  # how long `close` lets the worker finish before terminating it
PARENT_CHECK_S = 1.0  # how often an idle worker checks that its device is still there
NICE = 10  # the worker's niceness increment: on a busy machine its CPU goes to the streaming device first
ONE_THREAD = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
# The worker lowers its priority before it imports anything heavy (its start-up is a second of CPU, too).
BOOT = f"import os; os.nice({NICE}); from {__name__} import main; main()"


class SolveProcessError(RuntimeError):
    """A solve failed in the worker process (its traceback is the message), or the worker is gone."""


class ProcessSolves:
    """A `SolveBackend` whose solves run in one worker process; see the module docstring.

    Counters: ``starts`` (worker processes started), ``requests`` (solves sent to the worker).
    """

    def __init__(self, solver: FeatureSolver) -> None:
        """Nothing starts yet: the worker process starts on the first `solve`."""
        self.solver = solver
        self._popen: subprocess.Popen | None = None
        self._to: Connection | None = None  # requests, to the worker's stdin
        self._from: Connection | None = None  # replies, from the worker's stdout
        self._solve_lock = threading.Lock()  # one request in flight
        self._send_lock = threading.Lock()  # `close` may send the stop while a solve waits for its reply
        self._closed = False
        self.starts = self.requests = 0

    @property
    def pid(self) -> int | None:
        """The worker's process id while it runs, else None."""
        popen = self._popen
        return popen.pid if popen is not None and popen.poll() is None else None

    def solve(self, xy: np.ndarray) -> np.ndarray:
        """Exact features (N, E, C) of points (N, 2) screen mm, computed by the worker; blocks (without the GIL)
        until it answers. Raises `SolveProcessError` if the worker's solve raised or the worker is gone."""
        with self._solve_lock:
            to, back, popen = self._ensure_started()
            try:
                with self._send_lock:
                    to.send(np.ascontiguousarray(xy, dtype=float).reshape(-1, 2))
                self.requests += 1
                kind, value = back.recv()
            except (EOFError, OSError) as exc:
                raise SolveProcessError(f"solver process {popen.pid} is gone: {exc!r}") from exc
        if kind != "ok":
            raise SolveProcessError(value)
        return value

    def _ensure_started(self) -> tuple[Connection, Connection, subprocess.Popen]:
        """The running worker and its pipes; starts one if there is none (called with `_solve_lock` held)."""
        if self._closed:
            raise SolveProcessError("solver process closed")
        if self._popen is not None and self._popen.poll() is None:
            return self._to, self._from, self._popen
        self._reap()
        if self.starts >= MAX_STARTS:
            raise SolveProcessError(f"solver process failed {self.starts} times; not restarted")
        request_r, request_w = os.pipe()
        reply_r, reply_w = os.pipe()
        try:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p), **ONE_THREAD)
            popen = subprocess.Popen([sys.executable, "-c", BOOT, str(os.getpid())], stdin=request_r,
                                     stdout=reply_w, env=env, start_new_session=True)
        finally:
            os.close(request_r)
            os.close(reply_w)
        to, back = Connection(request_w, readable=False), Connection(reply_r, writable=False)
        self.starts += 1
        with self._send_lock:
            self._popen, self._to, self._from = popen, to, back
            with contextlib.suppress(OSError):  # if the worker died at once, the request below finds out
                to.send_bytes(pickle.dumps(self.solver))  # the only time the solver crosses
        if self._closed:  # closed while starting: `close` did not see this process
            self._stop(popen)
            raise SolveProcessError("solver process closed")
        return to, back, popen

    def _reap(self) -> None:
        """Forget a worker that is gone (collect its exit status, close its pipes)."""
        if self._popen is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._popen.wait(0)
        for conn in (self._to, self._from):
            if conn is not None:
                conn.close()
        self._popen = self._to = self._from = None

    def close(self) -> None:
        """Stop the worker: a stop message, `STOP_GRACE_S` to obey, then terminate and kill; idempotent."""
        with self._send_lock:
            self._closed = True
            popen = self._popen
        if popen is not None:
            self._stop(popen)
        with self._solve_lock:  # a solve that waited on the worker has returned (its process is dead)
            self._reap()

    def _stop(self, popen: subprocess.Popen) -> None:
        with self._send_lock, contextlib.suppress(OSError, ValueError, AttributeError):
            self._to.send(None)
        for finish in (None, popen.terminate, popen.kill):
            if finish is not None:
                finish()
            with contextlib.suppress(subprocess.TimeoutExpired):
                popen.wait(STOP_GRACE_S)
                return
        popen.wait()


def serve(requests: Connection, replies: Connection, parent_pid: int) -> None:
    """The worker: read the solver, then answer each request (points (N, 2)) with ("ok", features) or ("error",
    traceback) until a None request, a closed pipe or a new parent."""
    try:
        solver = pickle.loads(requests.recv_bytes())
    except (EOFError, OSError):
        return
    while True:
        try:
            if not requests.poll(PARENT_CHECK_S):
                if os.getppid() != parent_pid:
                    return  # the device died without closing us
                continue
            request = requests.recv()
        except (EOFError, OSError):
            return
        if request is None:
            return
        try:
            reply = ("ok", solver.solve(request))
        except Exception:  # reported to the device, which logs it; the next request may well succeed
            reply = ("error", traceback.format_exc())
        try:
            replies.send(reply)
        except OSError:
            return


def main() -> None:
    """The worker's entry (`BOOT`, argument PARENT_PID), started by `ProcessSolves`: requests on stdin, replies
    on stdout (anything else printed goes to stderr)."""
    requests = Connection(os.dup(0), writable=False)
    replies = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)  # a stray print must not corrupt the replies
    sys.stdout = sys.stderr
    serve(requests, replies, int(sys.argv[1]))
