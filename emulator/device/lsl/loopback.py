"""The loopback bind library (`loopback_bind.c`): built once with the system's C compiler, preloaded into the
LSL outlet process so that liblsl's data and time ports listen on 127.0.0.1 (liblsl has no option for them).

The library is compiled on first use into the cache folder (`cache_dir`: $EYEHIL_CACHE, else
$XDG_CACHE_HOME/eyehil, else ~/.cache/eyehil), named by a hash of its source so that a changed source is
rebuilt, and written atomically (compiled to a temporary name, then renamed). Without Linux or without a C
compiler (`$CC`, else `cc`), `library()` returns None and the reason: the outlet then runs without it and says
that its ports listen on all interfaces.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

SOURCE = Path(__file__).with_name("loopback_bind.c")
COUNTER = "eyehil_loopback_moved"  # the library's count of binds moved to the loopback
COMPILE_TIMEOUT_S = 120.0


class LibraryUnavailableError(Exception):
    """The library cannot be had here; the message says why."""


def cache_dir() -> Path:
    """Where built helpers are kept."""
    if os.environ.get("EYEHIL_CACHE"):
        return Path(os.environ["EYEHIL_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "eyehil"


def library(folder: Path | None = None) -> Path:
    """The built library (compiled now if it is not in `folder`, default `cache_dir()`), or LibraryUnavailableError."""
    if not sys.platform.startswith("linux"):
        raise LibraryUnavailableError(f"the loopback bind library needs Linux's LD_PRELOAD (this is {sys.platform})")
    source = SOURCE.read_bytes()
    folder = folder or cache_dir()
    target = folder / f"loopback_bind-{hashlib.sha256(source).hexdigest()[:16]}.so"
    if any(c in str(target) for c in " :"):  # LD_PRELOAD separates its entries by spaces and colons
        raise LibraryUnavailableError(f"LD_PRELOAD cannot name {target} (a space or colon): set EYEHIL_CACHE")
    if target.is_file():
        return target
    compiler = os.environ.get("CC") or "cc"
    if shutil.which(compiler) is None:
        raise LibraryUnavailableError(f"no C compiler ({compiler!r}, set CC) to build {SOURCE.name}")
    scratch = folder / f".{target.name}.{os.getpid()}.tmp"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        done = subprocess.run([compiler, "-shared", "-fPIC", "-O2", "-o", str(scratch), str(SOURCE), "-ldl"],
                              capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S, check=False)
        if done.returncode != 0:
            raise LibraryUnavailableError(f"{compiler} could not build {SOURCE.name}: {done.stderr.strip()[-500:]}")
        os.replace(scratch, target)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise LibraryUnavailableError(f"{compiler} could not build {SOURCE.name}: {exc}") from exc
    finally:
        scratch.unlink(missing_ok=True)
    return target


def preloaded(env: dict[str, str], path: Path) -> dict[str, str]:
    """A copy of `env` that preloads the library at `path` in front of whatever it preloaded already."""
    out = dict(env)
    out["LD_PRELOAD"] = " ".join(p for p in (str(path), env.get("LD_PRELOAD", "")) if p)
    return out


def moved_binds() -> int | None:
    """How many binds the library moved to the loopback in this process; None if it is not loaded here."""
    try:
        return ctypes.c_int.in_dll(ctypes.CDLL(None), COUNTER).value
    except ValueError:
        return None
