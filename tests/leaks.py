"""The leak check shared by the device, USB/IP and ZeroMQ suites (python-can's test/conftest.py idea).

`leak_check(...)` is a context manager around one test: afterwards no thread whose name starts with
`thread_prefix` may run, no emulator link may be registered open (`eyehil.emulator.device.links.base.open_links`),
and no descriptor of the given kinds (or listening TCP socket) opened during the test may remain.
Descriptors are read from Linux /proc; elsewhere only threads and links are checked.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from eyehil.emulator.device.links.base import open_links

PROC = os.path.isdir("/proc/self/fd")


def process_running(pid: int) -> bool:
    """True if process `pid` exists and is not a zombie (Linux /proc)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def descriptors(kinds: tuple[str, ...]) -> set[str]:
    """Open descriptors of this process whose target starts with one of `kinds` ("socket:", "pipe:", ...)."""
    found = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith(kinds):
            found.add(f"fd {fd} -> {target}")
    return found


def listening_sockets() -> set[str]:
    """Inodes of the listening TCP sockets (IPv4 and IPv6) this process holds."""
    ours = {t.split("[")[1][:-1] for t in (d.split(" -> ")[1] for d in descriptors(("socket:[",)))}
    listening = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            with open(table) as f:
                rows = [line.split() for line in f.readlines()[1:]]
        except OSError:
            continue
        listening |= {row[9] for row in rows if len(row) > 9 and row[3] == "0A"}
    return ours & listening


@contextmanager
def leak_check(
    thread_prefix: str = "eyehil", *, kinds: tuple[str, ...] = (), listening: bool = False
) -> Iterator[None]:
    """Fail (AssertionError) if the wrapped code leaves threads, links or descriptors behind."""

    def snapshot() -> set[str]:
        if not PROC:
            return set()
        return (descriptors(kinds) if kinds else set()) | (listening_sockets() if listening else set())

    before = snapshot()
    yield
    threads = [t.name for t in threading.enumerate() if t.name.startswith(thread_prefix)]
    assert not threads, f"threads left running: {threads}"
    assert not open_links(), f"links left open: {open_links()}"
    leaked = snapshot() - before
    assert not leaked, f"left open: {sorted(leaked)}"
