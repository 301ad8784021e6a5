"""pylsl and liblsl's configuration for the facade.

liblsl reads its configuration once per process from the file named by LSLAPICFG. Unless the user set
LSLAPICFG, `use_loopback_config` points it at `LOOPBACK_CONFIG` (written once to a temporary file, removed at
exit): stream discovery answers on 127.0.0.1 only (``ListenAddress``), within this machine (``ResolveScope =
machine``, multicast TTL 0), IPv4 only. The data and time ports are kept on the loopback by `loopback` (liblsl has no
option for them).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import tempfile

LOOPBACK_CONFIG = """[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
ListenAddress = 127.0.0.1
TTLOverride = 0
"""

_written: list[str] = []  # the configuration file this process wrote, if any


class LslUnavailableError(ImportError):
    """pylsl or its liblsl is missing (the message says which, and how to install it)."""


def use_loopback_config() -> str:
    """Point liblsl at `LOOPBACK_CONFIG` unless LSLAPICFG is set already; return the file liblsl will read."""
    if not os.environ.get("LSLAPICFG"):
        handle, path = tempfile.mkstemp(prefix="eyehil-lsl-", suffix=".cfg")
        with os.fdopen(handle, "w") as f:
            f.write(LOOPBACK_CONFIG)
        os.environ["LSLAPICFG"] = path
        _written.append(path)
        atexit.register(_remove, path)
    return os.environ["LSLAPICFG"]


def _remove(path: str) -> None:
    """Delete the configuration file at exit (liblsl read it when it loaded)."""
    with contextlib.suppress(OSError):
        os.remove(path)


def ours(path: str) -> bool:
    """`path` is the loopback configuration this process wrote (not one the user chose)."""
    return path in _written


def load_pylsl(loopback: bool = True):
    """The pylsl module, or LslUnavailableError; `loopback`: liblsl configured for the loopback first
    (`use_loopback_config`), else as LSLAPICFG or liblsl's defaults say."""
    if loopback:
        use_loopback_config()
    try:
        import pylsl
    except ImportError as exc:
        raise LslUnavailableError(f"the LSL outlet needs pylsl: pip install 'eyehil[lsl]' ({exc})") from exc
    except (RuntimeError, OSError) as exc:  # pylsl present, liblsl not found or not loadable
        raise LslUnavailableError(f"pylsl cannot load liblsl: {exc}") from exc
    return pylsl
