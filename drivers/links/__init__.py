"""Host-side links chosen by URL: an explicit scheme table with lazy imports (python-can style).

    link = open_link("socket://127.0.0.1:5555")    # or /dev/ttyACM0, loop://?clock=fast, spy://..., usbip://h:p

Every scheme also answers to ``eyehil+<scheme>://`` (the form pyserial's `serial_for_url` opens once eyehil is
imported, `eyehil.drivers.urlhandlers`).

SerialLike, the interface every scheme returns (a subset of pyserial's `Serial`; pyserial objects
qualify as they are)::

    timeout: float | None     seconds `read` may wait; 0 = return at once with what is there; None = block
    read(size=1) -> bytes     up to `size` bytes: returns as soon as `size` bytes are there or the timeout
                              expires (then fewer, possibly b""); raises OSError (pyserial: SerialException)
                              when the link is gone
    write(data) -> int|None   send all of `data` (may block briefly)
    close() -> None           release the link; idempotent
    optional:
    fileno() -> int           a descriptor select() can wait on (the client then reads with timeout 0)
    read_now(size) -> bytes   up to `size` bytes already there, in one system call, never waiting (b"" if none);
                              OSError when the link is gone. The client drains a link with it between two
                              select()s; pyserial's posix ports qualify without it (their descriptor is read)
    in_waiting: int           bytes readable now (informative)
    reset_input_buffer()      discard bytes received but not read (used once, when a client opens)

A new scheme is one module with a callable ``opener(url: str, *, timeout: float) -> SerialLike`` (a
function, or a dotted attribute such as a classmethod ``Class.from_url``) and one line in `SCHEMES`.
`loop://` is the only scheme served by the emulator package (an in-process device for tests, imported
by name only when used); the host still sees nothing but bytes.

Modules: `serialport` (device paths), `tcp` (socket://), `spy` (hex dump), `usbip` (usbip://) over
`usbip_client` (a small USB/IP client); `fault` (`FaultLink`: wraps any SerialLike and injects faults into
what it reads; tests, ``--fault`` on the host subcommands).
"""

from __future__ import annotations

import importlib
from typing import Protocol

from eyehil.drivers.errors import LinkError, SchemeUnavailableError

#: scheme -> (module, opener: a function or dotted attribute called as opener(url, timeout=...)).
#: "" is a plain device path (/dev/ttyACM0, /dev/pts/5, COM3).
SCHEMES: dict[str, tuple[str, str]] = {
    "": ("eyehil.drivers.links.serialport", "open_serial"),
    "socket": ("eyehil.drivers.links.tcp", "open_socket"),
    "rfc2217": ("eyehil.drivers.links.serialport", "open_serial"),
    "loop": ("eyehil.emulator.device.links.loop", "open_loop"),
    "spy": ("eyehil.drivers.links.spy", "open_spy"),
    "usbip": ("eyehil.drivers.links.usbip", "UsbipSerial.from_url"),
}
#: what to tell the user when a scheme's module is missing
INSTALL_HINTS: dict[str, str] = {
    "usbip": "usbip:// needs drivers/links/usbip.py (the USB/IP link)",
    "loop": "loop:// needs the eyehil emulator package",
}


class SerialLike(Protocol):
    """See the module docstring."""

    timeout: float | None

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    def close(self) -> None: ...


def scheme_of(url: str) -> str:
    """The URL's scheme ("" for a plain device path); ``eyehil+loop://`` (the pyserial form) is ``loop``."""
    head, sep, _ = url.partition("://")
    head = head.lower().removeprefix("eyehil+")
    return head if sep and head.isidentifier() else ""


def open_link(url: str, timeout: float | None = 0.0) -> SerialLike:
    """Open `url` with the function its scheme names in `SCHEMES`; raise `SchemeUnavailableError` or `LinkError`."""
    scheme = scheme_of(url)
    if scheme not in SCHEMES:
        raise SchemeUnavailableError(f"unknown link scheme {scheme!r} in {url!r}; known: {', '.join(sorted(SCHEMES))}")
    module_name, attribute = SCHEMES[scheme]
    try:
        opener = importlib.import_module(module_name)
        for name in attribute.split("."):
            opener = getattr(opener, name)
    except (ImportError, AttributeError) as exc:
        hint = INSTALL_HINTS.get(scheme, f"{module_name} is not available")
        raise SchemeUnavailableError(f"{url!r}: {hint} ({exc})") from exc
    url = url.removeprefix("eyehil+")
    try:
        return opener(url, timeout=timeout)
    except (OSError, ValueError) as exc:
        if isinstance(exc, LinkError):
            raise
        raise LinkError(f"cannot open {url!r}: {exc}") from exc
