"""pytest plugin ``eyehil``: fixtures serving a virtual eye tracker to the host code under test.

Installed with the package (entry point ``pytest11: eyehil``); documented in docs/pytest-plugin.md.

    def test_my_driver(eyehil_url):                 # an emulator on a pseudo-terminal, e.g. "/dev/pts/7"
        with MyDriver(eyehil_url) as tracker:       # the code under test opens it like a serial port
            ...

    @pytest.mark.eyehil(scene="blignaut2014", link="tcp", clock="real", rate_hz=500)
    def test_binocular(eyehil_url, eyehil_geometry): ...

Fixtures (function scope; each test gets a fresh device, closed afterwards):

- ``eyehil_options``: the `DeviceOptions` (defaults < command line < the test's ``eyehil`` marker);
- ``eyehil_emulator``: the running `LinkRunner` (``.url``; ``.core`` is the device, e.g. ``.core.status()``);
- ``eyehil_url``: what the host opens (a pseudo-terminal path; ``socket://127.0.0.1:PORT`` with link="tcp");
- ``eyehil_geometry``: the host's geometry file for the scene (TOML, in ``tmp_path``).

Command-line options: ``--eyehil-scene``, ``--eyehil-clock`` (fast | real; default fast), ``--eyehil-link``
(pty | tcp). Marker keywords: any `DeviceOptions` field, plus ``link``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import fields, replace
from pathlib import Path

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("eyehil", "virtual eye tracker (eyehil)")
    group.addoption("--eyehil-scene", default="guestrin2006", help="scene preset or TOML path (default guestrin2006)")
    group.addoption("--eyehil-clock", default="fast", choices=["fast", "real"], help="device clock (default fast)")
    group.addoption("--eyehil-link", default="pty", choices=["pty", "tcp"], help="link (default pty)")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "eyehil(**options): options of the virtual eye tracker (DeviceOptions, link)")


def _marker_options(request: pytest.FixtureRequest) -> dict:
    marker = request.node.get_closest_marker("eyehil")
    return dict(marker.kwargs) if marker else {}


@pytest.fixture
def eyehil_options(request: pytest.FixtureRequest):
    """`eyehil.emulator.device.build.DeviceOptions` for this test."""
    from eyehil.emulator.device.build import DeviceOptions

    wanted = {k: v for k, v in _marker_options(request).items() if k != "link"}
    known = {f.name for f in fields(DeviceOptions)}
    unknown = set(wanted) - known
    if unknown:
        raise pytest.UsageError(f"eyehil marker: unknown option(s) {sorted(unknown)}; known: {sorted(known)}")
    base = DeviceOptions(scene=request.config.getoption("eyehil_scene"), clock=request.config.getoption("eyehil_clock"))
    return replace(base, **wanted)


@pytest.fixture
def eyehil_emulator(request: pytest.FixtureRequest, eyehil_options) -> Iterator:
    """A running emulator (`eyehil.emulator.device.links.base.LinkRunner`), closed after the test."""
    from eyehil.emulator.device.build import build_device, paced
    from eyehil.emulator.device.links.base import LinkRunner

    kind = _marker_options(request).get("link", request.config.getoption("eyehil_link"))
    if kind == "tcp":
        from eyehil.emulator.device.links.tcp import TcpLink as Link
    elif kind == "pty":
        from eyehil.emulator.device.links.pty import PtyLink as Link
    else:
        raise pytest.UsageError(f"eyehil marker: link must be 'pty' or 'tcp', got {kind!r}")
    core = build_device(eyehil_options)
    try:
        runner = LinkRunner(core, paced(Link(), eyehil_options, core.clock)).start()
    except BaseException:
        core.close()
        raise
    try:
        yield runner
    finally:
        runner.close()


@pytest.fixture
def eyehil_url(eyehil_emulator) -> str:
    """The URL (pseudo-terminal path or socket://...) of the running emulator."""
    return eyehil_emulator.url


@pytest.fixture
def eyehil_geometry(eyehil_options, tmp_path: Path) -> Path:
    """The host's tracker geometry file for the emulator's scene."""
    from eyehil.emulator.device.setup_file import write_geometry
    from eyehil.emulator.scene import load_scene

    return write_geometry(load_scene(eyehil_options.scene), tmp_path / "eyehil-geometry.toml")
