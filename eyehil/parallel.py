"""Run per-eye work in parallel: a local process pool by default, a Dask cluster when given an address. Used by
`eyehil simulate`, the study and the discrepancy workflow.

Work is split into chunks of eyes; `run_chunks(func, chunks, ...)` returns the results in chunk order
and tells `progress(n_eyes)` as chunks finish; `iter_chunks` yields `(index, result)` as each chunk finishes,
so that a caller can write a chunk away before the next arrives (memory bounded by the chunks in flight).
`func` must be a module-level function (picklable).

Every worker, local or on Dask (and this process when it runs the chunks itself), first fixes glibc's malloc
thresholds (`tune_malloc`): the forward model's numpy temporaries (hundreds of kB to tens of MB each) then come
from the heap instead of a fresh mmap per array. Dask's nanny starts workers with `MALLOC_TRIM_THRESHOLD_=65536`,
which switches off glibc's dynamic mmap threshold and made the same work 2.7-3.4x slower there
(docs/benchmarks.md).

Ctrl-C (or any error) stops the work at once: the queued chunks are cancelled and the worker processes
terminated, rather than waited for; the workers ignore SIGINT themselves (a terminal's Ctrl-C reaches the whole
process group), so the main process alone decides and no worker prints a traceback. SIGINT is blocked while the
workers are forked (`submit` forks them), so that none can see a Ctrl-C before it ignores it; a Ctrl-C in that
moment waits, pending, and is delivered once the workers exist. A worker ends by itself once the process that
started it is gone (`exit_with_parent`), so a main process killed with SIGKILL leaves no worker behind; the
render processes of `eyehil emulate` do the same.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from multiprocessing.connection import wait
from typing import Any

#: s to wait for each terminated worker to exit
JOIN_TIMEOUT_S = 5.0
#: s between a worker's checks that the process that started it is still there (`exit_with_parent`)
PARENT_POLL_S = 0.5
#: glibc mallopt parameters and the values `tune_malloc` sets: allocations up to 32 MiB (glibc's largest mmap
#: threshold on 64-bit) come from the heap, and up to 256 MiB of freed heap stay with the process
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
TRIM_THRESHOLD_BYTES = 256 * 1024 * 1024
_malloc_tuned = False


def default_workers() -> int:
    """One worker per available core."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_chunks(func: Callable[..., Any], chunks: Sequence[Any], **options: Any) -> list[Any]:
    """func(chunk, **kwargs) for every chunk, in chunk order: `iter_chunks` (its options: sizes, workers,
    scheduler, progress, and the keyword arguments of `func`) gathered into a list."""
    results: list[Any] = [None] * len(chunks)
    for i, result in iter_chunks(func, chunks, **options):
        results[i] = result
    return results


def iter_chunks(
    func: Callable[..., Any],
    chunks: Sequence[Any],
    *,
    sizes: Sequence[int],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
    **kwargs: Any,
) -> Iterator[tuple[int, Any]]:
    """(chunk index, func(chunk, **kwargs)) as each chunk finishes: in this process and in order when `workers` is
    1 (or there is one chunk), on a local process pool of `workers` (default one per core), or on the Dask
    cluster at `scheduler`. `progress(sizes[i])` is told after the caller has taken each result. Leaving the loop
    early (an error, Ctrl-C) stops the work at once."""
    tell = progress or (lambda n: None)
    if scheduler:
        yield from _iter_dask(func, chunks, sizes, scheduler, tell, kwargs)
        return
    workers = workers or default_workers()
    if workers <= 1 or len(chunks) <= 1:
        tune_malloc()
        for i, (chunk, size) in enumerate(zip(chunks, sizes, strict=True)):
            yield i, func(chunk, **kwargs)
            tell(size)
        return
    with worker_pool(workers) as pool:
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            futures = {pool.submit(func, chunk, **kwargs): i for i, chunk in enumerate(chunks)}
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        for future in as_completed(futures):
            i = futures.pop(future)
            yield i, future.result()
            tell(sizes[i])


@contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A process pool whose workers ignore Ctrl-C; if the block raises (Ctrl-C included) the pool is stopped at
    once (`stop_pool`), otherwise shut down as usual (waiting for the work)."""
    pool = ProcessPoolExecutor(max_workers=workers, initializer=_init_worker, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()


def tune_malloc() -> bool:
    """Set glibc's mmap and trim thresholds for this process (once; see the module docstring). True when they
    are set: False where the C library is not glibc (nothing to do there) or refused them."""
    global _malloc_tuned
    if not _malloc_tuned and sys.platform.startswith("linux"):
        try:
            mallopt = ctypes.CDLL("libc.so.6").mallopt
        except (OSError, AttributeError):  # musl or another C library: its own allocator, left as it is
            return False
        _malloc_tuned = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
                             and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    return _malloc_tuned


def tuned_call(func: Callable[..., Any], chunk: Any, **kwargs: Any) -> Any:
    """func(chunk, **kwargs) after `tune_malloc` (how a Dask worker runs a chunk)."""
    tune_malloc()
    return func(chunk, **kwargs)


def _init_worker(parent: int | None = None) -> None:
    """Worker initializer: Ctrl-C is the main process's to handle (it terminates the workers); SIGTERM takes its
    default action whatever handler the forked parent had installed (terminate must end a worker); malloc's
    thresholds are fixed (`tune_malloc`); the worker ends with `parent`, the pool's process (`exit_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    tune_malloc()
    exit_with_parent(parent)


def exit_with_parent(parent: int | None = None, poll_s: float = PARENT_POLL_S) -> threading.Thread:
    """End this process (`os._exit`) once its parent is no longer process `parent` (default: the parent it has
    now), checked every `poll_s` on a daemon thread.

    A pool worker waits for its next task on a pipe whose other end it holds itself, so a parent killed with
    SIGKILL (or by the out-of-memory killer) left its workers waiting forever. Pass the starting process's id,
    taken in that process: a worker that starts after its parent has died then ends at once, instead of taking
    its new parent for the old one. (Linux's PR_SET_PDEATHSIG follows the thread that started the worker, not
    the process.)"""
    parent = os.getppid() if parent is None else parent

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    thread = threading.Thread(target=watch, name="eyehil-exit-with-parent", daemon=True)
    thread.start()
    return thread


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel what is queued and terminate the workers now, instead of waiting for the running chunks.

    A worker's end is read from its sentinel, not from `join`: the pool's own manager thread reaps the workers
    too, and the thread that loses that `waitpid` race sees the worker as still running (ECHILD) until the winner
    records the exit code. Joining the manager thread last leaves every worker's exit code recorded."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown forgets them
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        if not _ended(process):  # did not take SIGTERM in time: no worker outlives the pool
            process.kill()
            _ended(process)
    if manager is not None:
        manager.join(JOIN_TIMEOUT_S)
    for process in processes:
        process.join(0)


def _ended(process: Any) -> bool:
    """True once the worker has exited (its sentinel is ready), waiting up to JOIN_TIMEOUT_S."""
    return bool(wait([process.sentinel], JOIN_TIMEOUT_S))


def _iter_dask(func, chunks, sizes, address: str, tell, kwargs) -> Iterator[tuple[int, Any]]:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:  # the optional extra
        raise RuntimeError("--scheduler needs the optional extra: pip install 'eyehil[dask]'") from exc
    with Client(address) as client:
        held: list[Any] = [client.submit(tuned_call, func, chunk, pure=False, **kwargs) for chunk in chunks]
        index = {f.key: i for i, f in enumerate(held)}
        try:
            for future in dask_completed(held):
                i = index[future.key]
                result = future.result()
                held[i] = future = None  # the cluster forgets a result once the caller has it
                yield i, result
                tell(sizes[i])
        except BaseException:  # Ctrl-C, an error, or the caller leaving early: the cluster stops this work too
            client.cancel([f for f in held if f is not None])
            raise
