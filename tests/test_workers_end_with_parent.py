"""Worker processes end with the process that started them, even when it is killed with SIGKILL
(`eyehil.parallel.exit_with_parent`): before, a killed `eyehil emulate` left its render processes waiting for
work forever, and a killed study its pool workers."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(not hasattr(os, "pidfd_open"), reason="waits on pidfds (Linux >= 5.3)")

SCRIPT = """
import signal, sys
kind = sys.argv[1]
if kind == "render":
    from eyehil.emulator.device.build import DeviceOptions, build_subject
    from eyehil.emulator.device.frames import ExposureRenderer
    from eyehil.emulator.device.render_pool import RenderPool
    pool = RenderPool(ExposureRenderer.for_subject(build_subject(DeviceOptions())), workers=2)
else:
    from eyehil.parallel import worker_pool
    pools = worker_pool(2)  # kept: the generator closes its pool when collected
    pool = pools.__enter__()
    assert [f.result() for f in [pool.submit(abs, -i) for i in range(8)]] == list(range(8))
print("ready", flush=True)
signal.pause()  # until the test kills this process
"""


def _children(pid: int) -> list[int]:
    """The processes whose parent is `pid`."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rpartition(")")[2].split()
            except OSError:  # gone meanwhile
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


@pytest.mark.parametrize("kind", ["render", "study"])
def test_workers_end_when_their_parent_is_killed(kind) -> None:
    parent = subprocess.Popen([sys.executable, "-c", SCRIPT, kind], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout.readline().strip() == "ready"
        workers = _children(parent.pid)
        assert len(workers) >= 2, workers  # the two workers (and, for spawn, multiprocessing's resource tracker)
        handles = {pid: os.pidfd_open(pid) for pid in workers}
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    try:
        left = dict(handles)
        while left:  # every child ends: wait for the pidfds to become readable (bounded, not a deadline to meet)
            ready, _, _ = select.select(list(left.values()), [], [], 60.0)
            assert ready, f"still running 60 s after their parent was killed: {sorted(left)}"
            left = {pid: fd for pid, fd in left.items() if fd not in ready}
    finally:
        for fd in handles.values():
            os.close(fd)
