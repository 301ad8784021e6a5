"""Fixtures of the ZeroMQ facade tests: a leak check on every test, the clients' context, servers to test.

`no_leaks` (autouse) fails a test that leaves an emulator thread ("eyehil-..."), an open server (the links
registry) or a listening TCP socket of this process behind (the facade's REP, XSUB and XPUB, or an LSL
outlet's). `client_context` (autouse) gives `zmq.Context.instance()`, which the real client uses, a receive
timeout and linger 0 before any client exists, so that a dead server raises instead of hanging the suite.
`server`, `device_of` and `subscribe` make facades, real clients and their subscriptions, closed after the test.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
import zmq
from leaks import leak_check
from pupil_labs.pupil_core_network_client import Device
from zmq_helpers import start_server

from eyehil.emulator.device.pupil.server import PupilServer

CLIENT_TIMEOUT_MS = 10_000


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves a facade thread, server or listening socket behind."""
    with leak_check("eyehil", listening=True):
        yield


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


@pytest.fixture
def device_of():
    """device_of(server) -> a connected real client; disconnected after the test."""
    made = []

    def connect(server) -> Device:
        made.append(Device("127.0.0.1", server.port))
        return made[-1]

    yield connect
    for d in made:
        d.disconnect()


@pytest.fixture
def subscribe():
    """subscribe(device, topics) -> a background subscription; disconnected after the test."""
    subs = []

    def make(device: Device, topics):
        subs.append(device.subscribe_in_background(topics, buffer_size=2000))
        return subs[-1]

    yield make
    for s in subs:
        s.disconnect()
