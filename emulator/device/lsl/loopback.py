"""The loopback bind library (`loopback_bind.c`): built once with the system's C compiler, preloaded into the
LSL outlet process so that liblsl's data and time ports listen on 127.0.0.1 (liblsl has no option for them).

The library is compiled on first use into the cache folder (`eyehil.cbuild`: $EYEHIL_CACHE, else
$XDG_CACHE_HOME/eyehil, else ~/.cache/eyehil), named by a hash of its source so that a changed source is
rebuilt, and written atomically (compiled to a temporary name, then renamed). Without Linux or without a C
compiler (`$CC`, else `cc`), `library()` returns None and the reason: the outlet then runs without it and says
that its ports listen on all interfaces.
"""

from __future__ import annotations

import ctypes
import sys
from pathlib import Path

from eyehil.cbuild import BuildUnavailableError, build, cache_dir

SOURCE = Path(__file__).with_name("loopback_bind.c")
COUNTER = "eyehil_loopback_moved"  # the library's count of binds moved to the loopback


class LibraryUnavailableError(Exception):
    """The library cannot be had here; the message says why."""


def library(folder: Path | None = None) -> Path:
    """The built library (compiled now if it is not in `folder`, default `cache_dir()`), or LibraryUnavailableError."""
    if not sys.platform.startswith("linux"):
        raise LibraryUnavailableError(f"the loopback bind library needs Linux's LD_PRELOAD (this is {sys.platform})")
    folder = folder or cache_dir()
    if any(c in str(folder) for c in " :"):  # LD_PRELOAD separates its entries by spaces and colons
        raise LibraryUnavailableError(f"LD_PRELOAD cannot name a library in {folder} (a space or colon): "
                                      "set EYEHIL_CACHE")
    try:
        return build(SOURCE, folder, libs=("-ldl",))
    except BuildUnavailableError as exc:
        raise LibraryUnavailableError(str(exc)) from exc


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
