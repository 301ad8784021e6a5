"""Fixtures of the firmware-in-the-loop tests: the firmware built once per session (skipped without a C
compiler), a factory of running firmware rigs (each closed after its test, asserting the firmware exited
cleanly), and a leak check on every test (threads "eyehil...", sockets, pipes, pseudo-terminals)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from firmware_helpers import FirmwareBuild, FirmwareRig, build_firmware, compiler_missing
from host_deadlines import generous
from leaks import leak_check


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves a sensor thread, socket, pipe or pseudo-terminal open."""
    with leak_check("eyehil", kinds=("socket:", "pipe:", "/dev/ptmx", "/dev/pts/")):
        yield


@pytest.fixture(autouse=True)
def generous_host_deadlines(monkeypatch: pytest.MonkeyPatch) -> None:
    """The host waits generously for replies and samples (a busy machine; tests/host_deadlines.py)."""
    generous(monkeypatch)


@pytest.fixture(scope="session")
def firmware_build(tmp_path_factory: pytest.TempPathFactory) -> FirmwareBuild:
    """`make` into a temporary directory, once per session."""
    reason = compiler_missing()
    if reason:
        pytest.skip(reason)
    return build_firmware(tmp_path_factory.mktemp("firmware-build"))


@pytest.fixture
def rig(firmware_build: FirmwareBuild) -> Iterator[Callable[..., FirmwareRig]]:
    """A factory: rig(**device options) -> a running `FirmwareRig`; every rig is closed after the test and
    its firmware must have exited with status 0."""
    rigs: list[FirmwareRig] = []

    def make(**options: object) -> FirmwareRig:
        rigs.append(FirmwareRig(firmware_build.firmware, **options))
        return rigs[-1]

    yield make
    statuses = [r.close(check=False) for r in rigs]
    assert all(s == 0 for s in statuses), f"firmware exit statuses: {statuses}"
