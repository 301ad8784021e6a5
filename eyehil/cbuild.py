"""Build a C source shipped with the package into a shared library, once, on first use.

The library goes into the cache folder (`cache_dir`: $EYEHIL_CACHE, else $XDG_CACHE_HOME/eyehil, else
~/.cache/eyehil), named by the source's stem and a hash of its bytes and the compiler's flags, so that a changed
source is rebuilt; it is compiled to a temporary name and renamed, so processes that build it at once never load a
half-written file. Without a C compiler (`$CC`, else `cc`) or when the build fails, `build` raises
`BuildUnavailableError` with the reason, and the caller runs without the library. `load` builds and loads a
library of compiled kernels, or says why not: EYEHIL_PURE_PYTHON=1 asks every caller to run its Python path.

A leaf below the layers (tests/test_house.py): it imports no eyehil module.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path

COMPILE_TIMEOUT_S = 120.0


class BuildUnavailableError(Exception):
    """The library cannot be built here; the message says why."""


def cache_dir() -> Path:
    """Where built libraries are kept."""
    if os.environ.get("EYEHIL_CACHE"):
        return Path(os.environ["EYEHIL_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "eyehil"


def build(source: Path, folder: Path | None = None, flags: Sequence[str] = ("-O2",), libs: Sequence[str] = ()) -> Path:
    """The shared library built from `source` into `folder` (default `cache_dir()`), compiled now if absent."""
    text = source.read_bytes()
    key = hashlib.sha256(text + "\0".join((*flags, *libs)).encode()).hexdigest()[:16]
    folder = folder or cache_dir()
    target = folder / f"{source.stem}-{key}.so"
    if target.is_file():
        return target
    compiler = os.environ.get("CC") or "cc"
    if shutil.which(compiler) is None:
        raise BuildUnavailableError(f"no C compiler ({compiler!r}, set CC) to build {source.name}")
    scratch = folder / f".{target.name}.{os.getpid()}.tmp"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        done = subprocess.run([compiler, "-shared", "-fPIC", *flags, "-o", str(scratch), str(source), *libs],
                              capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S, check=False)
        if done.returncode != 0:
            raise BuildUnavailableError(f"{compiler} could not build {source.name}: {done.stderr.strip()[-500:]}")
        os.replace(scratch, target)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise BuildUnavailableError(f"{compiler} could not build {source.name}: {exc}") from exc
    finally:
        scratch.unlink(missing_ok=True)
    return target


def load(source: Path, declare: Callable[[ctypes.CDLL], None], flags: Sequence[str] = ("-O2",)
         ) -> tuple[ctypes.CDLL | None, str]:
    """The library of kernels built from `source`, its functions typed by `declare`, and ""; or None and why not
    (EYEHIL_PURE_PYTHON is set, or the library cannot be built or loaded)."""
    if os.environ.get("EYEHIL_PURE_PYTHON"):
        return None, "EYEHIL_PURE_PYTHON is set"
    try:
        lib = ctypes.CDLL(str(build(source, flags=flags)))
    except (BuildUnavailableError, OSError) as exc:
        return None, str(exc)
    declare(lib)
    return lib, ""
