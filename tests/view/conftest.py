"""Fixtures of the live-view tests: a device on TCP, the view serving it, and a real headless Chromium.

Chromium comes from Debian's packages (``apt-get install chromium``), driven by Playwright's Python package
against that system browser (no browser download). The browser tests skip, with the reason, only when
Chromium or Playwright is absent.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from view_helpers import CHROMIUM, CHROMIUM_ARGS, start_device

from eyehil.drivers.setup_file import load_geometry
from eyehil.drivers.view.server import ViewServer
from eyehil.emulator.device.links.base import LinkRunner
from eyehil.emulator.device.setup_file import write_geometry
from eyehil.emulator.scene import load_scene


@pytest.fixture
def geometry_file(tmp_path: Path):
    def make(scene: str = "guestrin2006") -> Path:
        return write_geometry(load_scene(scene), tmp_path / f"{scene}.toml")
    return make


@pytest.fixture
def device() -> Iterator[LinkRunner]:
    runner = start_device()
    yield runner
    runner.close()


@pytest.fixture
def view(device, geometry_file) -> Iterator[ViewServer]:
    geometry = load_geometry(geometry_file()).geometry
    with ViewServer(device.url, geometry=geometry, plan_timing={"settle_s": 0.4, "collect_s": 0.15}) as server:
        yield server


@pytest.fixture(scope="session")
def browser():
    if not Path(CHROMIUM).exists() and not shutil.which("chromium"):
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")
    with sync_api.sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture
def page(browser, view):
    page = browser.new_page(viewport={"width": 1280, "height": 820})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(view.address)
    yield page
    page.close()
    assert not errors, f"JavaScript errors on the page: {errors}"
