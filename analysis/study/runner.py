"""Run per-eye work in parallel: a local process pool by default, a Dask cluster when given an address.

Work is split into chunks of eyes; `run_chunks(func, chunks, ...)` returns the results in chunk order
and tells `progress(n_eyes)` as chunks finish. `func` must be a module-level function (picklable).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any


def default_workers() -> int:
    """One worker per available core."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_chunks(
    func: Callable[..., Any],
    chunks: Sequence[Any],
    *,
    sizes: Sequence[int],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int], None] | None = None,
    **kwargs: Any,
) -> list[Any]:
    """func(chunk, **kwargs) for every chunk; serial when workers == 1, Dask when `scheduler` is set."""
    tell = progress or (lambda n: None)
    if scheduler:
        return _run_dask(func, chunks, sizes, scheduler, tell, kwargs)
    workers = workers or default_workers()
    if workers <= 1 or len(chunks) <= 1:
        out = []
        for chunk, size in zip(chunks, sizes, strict=True):
            out.append(func(chunk, **kwargs))
            tell(size)
        return out
    results: list[Any] = [None] * len(chunks)
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(func, chunk, **kwargs): i for i, chunk in enumerate(chunks)}
        for future in as_completed(futures):
            i = futures[future]
            results[i] = future.result()
            tell(sizes[i])
    return results


def _run_dask(func, chunks, sizes, address: str, tell, kwargs) -> list[Any]:
    try:
        from distributed import Client
        from distributed import as_completed as dask_completed
    except ImportError as exc:  # the optional extra
        raise RuntimeError("--scheduler needs the optional extra: pip install 'eyehil[dask]'") from exc
    with Client(address) as client:
        futures = [client.submit(func, chunk, pure=False, **kwargs) for chunk in chunks]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(chunks)
        for future in dask_completed(futures):
            i = index[future.key]
            results[i] = future.result()
            tell(sizes[i])
    return results
