"""The study at scale (issue 16): `eyehil study`'s work on N Rozema 2011 eyes (default 10,000; `python -m bench
study --eyes N`), end to end with its outputs and figures, on the local process pool and on a 2-worker Dask
LocalCluster: wall time, and the peak memory (RSS summed over the tree) and CPU time of the whole process tree
(this process, its workers and the cluster's processes; sampled every 0.2 s). Target: under 2 GB, and the two
runs' per-eye results equal.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.report import write_outputs
from eyehil.analysis.study.summary import summarise_study
from eyehil.emulator.eye.population import sample

TARGET_BYTES = 2 * 1024**3
SAMPLE_S = 0.2


def _tree(root: int) -> dict[int, tuple[int, int]]:
    """pid -> (RSS bytes, CPU clock ticks used) of `root` and all its descendants (Linux /proc)."""
    children: dict[int, list[int]] = {}
    stats: dict[int, tuple[int, int]] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        pid, ppid = int(entry.name), int(fields[1])
        children.setdefault(ppid, []).append(pid)
        # fields after the command: state ppid ... utime(12) stime(13) ... rss(22), counted from state = 0
        stats[pid] = (int(fields[21]) * PAGE, int(fields[11]) + int(fields[12]))
    out, todo = {}, [root]
    while todo:
        pid = todo.pop()
        if pid in stats:
            out[pid] = stats[pid]
        todo.extend(children.get(pid, []))
    return out


PAGE = os.sysconf("SC_PAGE_SIZE")
TICKS = os.sysconf("SC_CLK_TCK")


class TreeMonitor:
    """While the block runs (a thread samples every SAMPLE_S): the largest RSS of the whole process tree (this
    process, pool workers, a Dask cluster's processes), and the CPU the tree used (each process's last sampled
    CPU time, so a process that lived less than a sample interval is missed)."""

    def __enter__(self) -> TreeMonitor:
        self.peak, self._ticks, self._stop = 0, {}, threading.Event()
        self._before = dict(self._ticks_now())
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _ticks_now(self) -> dict[int, int]:
        tree = _tree(os.getpid())
        self.peak = max(self.peak, sum(rss for rss, _ in tree.values()))
        return {pid: ticks for pid, (_, ticks) in tree.items()}

    def _watch(self) -> None:
        while True:
            for pid, ticks in self._ticks_now().items():
                self._ticks[pid] = max(ticks, self._ticks.get(pid, 0))
            if self._stop.wait(SAMPLE_S):
                return

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join()
        self.cpu_seconds = sum(t - self._before.get(pid, 0) for pid, t in self._ticks.items()) / TICKS


def _one(eyes, out: Path, **kwargs) -> tuple[dict[str, float], np.ndarray]:
    with TreeMonitor() as tree:
        start = time.perf_counter()
        result = run_study(eyes, **kwargs)
        write_outputs(result, summarise_study(result), out)
        wall = time.perf_counter() - start
    return {"seconds": wall, "cpu_seconds": tree.cpu_seconds, "peak_bytes": tree.peak}, result.h1


def run(repeats: int = 1, eyes: int = 10_000) -> dict[str, float]:
    draw = sample(eyes, np.random.default_rng(2023)).eyes
    out: dict[str, float] = {"eyes": len(draw)}
    with tempfile.TemporaryDirectory() as tmp:
        local, h1 = _one(draw, Path(tmp) / "local")
        out.update({f"local_{k}": v for k, v in local.items()})
        try:
            from distributed import LocalCluster
        except ImportError:
            out["dask_missing"] = 1.0
            return out
        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
            dask, h1_dask = _one(draw, Path(tmp) / "dask", scheduler=cluster.scheduler_address)
        out.update({f"dask_{k}": v for k, v in dask.items()})
        out["max_difference_deg"] = float(np.nanmax(np.abs(h1 - h1_dask)))
    return out


def report(r: dict[str, float]) -> str:
    def part(name: str) -> str:
        peak = r[f"{name}_peak_bytes"]
        verdict = "PASS" if peak < TARGET_BYTES else "FAIL"
        return (f"{r[f'{name}_seconds']:.0f} s wall, {r[f'{name}_cpu_seconds']:.0f} s CPU, peak memory "
                f"{peak / 1024**2:,.0f} MiB (target < 2 GiB: {verdict})")

    text = f"study on {r['eyes']:,.0f} Rozema eyes, outputs and figures; local: {part('local')}"
    if "dask_missing" in r:
        return text + "; Dask: not installed (pip install 'eyehil[dask]')"
    same = "equal" if r["max_difference_deg"] == 0 else f"differ by up to {r['max_difference_deg']:.1e} deg"
    return f"{text}; Dask LocalCluster, 2 workers: {part('dask')}; per-eye H1 {same}"
