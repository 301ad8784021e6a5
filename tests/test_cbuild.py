"""eyehil.cbuild: C kernels built once into the cache, rebuilt when their source or flags change, and a reason
instead of a library where they cannot be built."""

from __future__ import annotations

import ctypes
import os
import shutil
from pathlib import Path

import pytest

from eyehil.cbuild import BuildUnavailableError, build, cache_dir, load

NEEDS_CC = pytest.mark.skipif(shutil.which(os.environ.get("CC") or "cc") is None, reason="no C compiler here")
SOURCE = "int twice(int x) { return 2 * x; }\n"


def _declare(lib: ctypes.CDLL) -> None:
    lib.twice.argtypes = (ctypes.c_int,)
    lib.twice.restype = ctypes.c_int


@pytest.fixture
def source(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("EYEHIL_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("EYEHIL_PURE_PYTHON", raising=False)
    path = tmp_path / "twice.c"
    path.write_text(SOURCE)
    return path


def test_the_cache_folder_follows_the_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("EYEHIL_CACHE", str(tmp_path / "here"))
    assert cache_dir() == tmp_path / "here"
    monkeypatch.delenv("EYEHIL_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "eyehil"


@NEEDS_CC
def test_a_library_is_built_once_and_rebuilt_when_its_source_or_flags_change(source: Path, tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    first = build(source)
    assert first.parent == tmp_path / "cache" and first.name.startswith("twice-") and first.is_file()
    assert not [p for p in first.parent.iterdir() if p.name.endswith(".tmp")]  # the scratch file is gone
    assert build(source, flags=("-O1",)) != first
    source.write_text(SOURCE + "int thrice(int x) { return 3 * x; }\n")
    changed = build(source)
    assert changed != first
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    assert build(source) == changed  # in the cache: no compiler needed


@NEEDS_CC
def test_load_types_the_functions_and_they_run(source: Path) -> None:
    lib, reason = load(source, _declare)
    assert reason == "" and lib is not None
    assert lib.twice(21) == 42


def test_load_says_why_not(source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EYEHIL_PURE_PYTHON", "1")
    assert load(source, _declare) == (None, "EYEHIL_PURE_PYTHON is set")
    monkeypatch.delenv("EYEHIL_PURE_PYTHON")
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    lib, reason = load(source, _declare)
    assert lib is None and "no C compiler" in reason and "no-such-cc" in reason


@NEEDS_CC
def test_a_source_that_does_not_compile_gives_the_compilers_message(source: Path) -> None:
    source.write_text("int broken(int x) { return x +; }\n")
    with pytest.raises(BuildUnavailableError, match=r"could not build twice\.c"):
        build(source)
    lib, reason = load(source, _declare)
    assert lib is None and "error" in reason
    assert not list((source.parent / "cache").glob("*.so"))
