"""The built wheel installs one import name, `eyehil`, and works in a fresh environment without the extras.

Builds the wheel, installs it (with its dependencies, from the package index or pip's cache) into a new
virtual environment, and runs there, outside the source tree: `import eyehil`, `eyehil --version`,
`eyehil emulate --help`, `eyehil study --help`, and the README's pytest-plugin example. Slow (about a
minute when pip's cache is warm): it is the only test that sees eyehil as a user installs it.
"""

from __future__ import annotations

import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

README_EXAMPLE = '''
import serial

from eyehil.protocols.messages import Start
from eyehil.protocols.native import encode


def test_my_driver_reads_features(eyehil_url):
    port = serial.Serial(eyehil_url, timeout=1.0)   # a real pty speaking docs/protocol.md
    port.write(encode(Start(), seq=1, timestamp_us=0))
    assert port.read(64)
    port.close()
'''


def _run(*cmd: str | Path, cwd: Path) -> str:
    done = subprocess.run([str(c) for c in cmd], cwd=cwd, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, f"{cmd}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    _run(sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", out, ROOT, cwd=out)
    (found,) = out.glob("eyehil-*.whl")
    return found


@pytest.fixture(scope="module")
def fresh(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A new virtual environment with the wheel and pytest installed; returns its bin folder."""
    home = tmp_path_factory.mktemp("venv")
    venv.create(home / "v", with_pip=True)
    bin_ = home / "v" / "bin"
    _run(bin_ / "python", "-m", "pip", "install", "--quiet", wheel, "pytest", cwd=home)
    return bin_


def test_the_wheel_has_one_top_level_name(wheel: Path) -> None:
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith((".dist-info", ".data"))}
    assert tops == {"eyehil"}
    assert {"eyehil/py.typed", "eyehil/emulator/scene/presets/guestrin2006.toml",
            "eyehil/emulator/data/fischer2023_eyes.csv", "eyehil/analysis/study/data/published_results.json",
            "eyehil/drivers/urlhandlers/protocol_eyehil+loop.py",
            "eyehil/emulator/device/lsl/loopback_bind.c", "eyehil/protocols/kernels.c",
            "eyehil/emulator/render/kernels.c"} <= set(names)
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    text = zipfile.ZipFile(wheel).read(entry_points).decode()
    assert "eyehil = eyehil.cli:main" in text and "eyehil = eyehil.emulator.device.pytest_plugin" in text


def test_import_without_extras_and_the_commands_run(fresh: Path, tmp_path: Path) -> None:
    code = ("import importlib.util as u, eyehil; "
            "print(eyehil.__version__, [m for m in ('usb', 'pylsl', 'dask') if u.find_spec(m)])")
    out = _run(fresh / "python", "-c", code, cwd=tmp_path)
    version, extras = out.split(" ", 1)
    assert version == "0.1.0" and extras.strip() == "[]"
    assert _run(fresh / "eyehil", "--version", cwd=tmp_path).strip() == "eyehil 0.1.0"
    assert "--link" in _run(fresh / "eyehil", "emulate", "--help", cwd=tmp_path)
    assert "fischer2023" in _run(fresh / "eyehil", "study", "--help", cwd=tmp_path)


def test_the_readme_pytest_plugin_example_runs(fresh: Path, tmp_path: Path) -> None:
    (tmp_path / "test_user.py").write_text(README_EXAMPLE)
    out = _run(fresh / "python", "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_user.py", cwd=tmp_path)
    assert "1 passed" in out
