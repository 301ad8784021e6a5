"""Fixtures of the ZeroMQ facade tests: a leak check on every test, the clients' context, servers to test.

`no_leaks` (autouse) fails a test that leaves an emulator thread ("eyehil-..."), an open server (the links
registry) or a listening TCP socket of this process behind (the facade's REP, XSUB and XPUB, or an LSL
outlet's). `client_context` (autouse) gives `zmq.Context.instance()`, which the real client uses, a receive
timeout and linger 0 before any client exists, so that a dead server raises instead of hanging the suite.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator

import pytest
import zmq
from zmq_helpers import start_server

from emulator.device.links import open_links
from emulator.device.zmq_server import PupilServer

CLIENT_TIMEOUT_MS = 10_000


def _listening() -> set[str]:
    """Inodes of the listening TCP sockets (IPv4 and IPv6) that this process holds (Linux /proc)."""
    ours = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            ours.add(target[8:-1])
    listening = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            with open(table) as f:
                rows = [line.split() for line in f.readlines()[1:]]
        except OSError:
            continue
        listening |= {row[9] for row in rows if len(row) > 9 and row[3] == "0A"}
    return ours & listening


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves a facade thread, server or listening socket behind."""
    linux = os.path.isdir("/proc/self/fd")
    before = _listening() if linux else set()
    yield
    threads = [t.name for t in threading.enumerate() if t.name.startswith("eyehil")]
    assert not threads, f"emulator threads left running: {threads}"
    assert not open_links(), f"servers left open: {open_links()}"
    leaked = (_listening() - before) if linux else set()
    assert not leaked, f"listening sockets left open: {sorted(leaked)}"


@pytest.fixture(autouse=True)
def client_context() -> zmq.Context:
    """The real client's shared context, with a receive timeout and linger 0."""
    ctx = zmq.Context.instance()
    ctx.rcvtimeo = CLIENT_TIMEOUT_MS
    ctx.linger = 0
    return ctx


@pytest.fixture
def server() -> Iterator[Callable[..., PupilServer]]:
    """A factory: server(scene=..., latency=..., **ServerOptions fields) -> a started facade on a free port;
    every one is closed after the test."""
    started: list[PupilServer] = []

    def make(**options: object) -> PupilServer:
        started.append(start_server(**options))
        return started[-1]

    yield make
    for s in started:
        s.close()
