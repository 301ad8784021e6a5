"""Listening sockets of the device's servers, with one clear error when they cannot bind.

`create_server(link, host, port)` is `socket.create_server` that checks the port (0..65535, 0 = any free
port) and turns a failure to bind into `ListenError`: ``cannot listen on tcp 127.0.0.1:4242: address already
in use``, naming the link, the address and the reason (the `eyehil` command prints it as one line, exit 1).
`listen_error` makes the same error from another library's failure (ZeroMQ's).
"""

from __future__ import annotations

import errno
import os
import socket
from typing import Any

MAX_PORT = 65535


class ListenError(OSError):
    """A server of the device could not listen on its address; the message names the link, address and reason."""


def check_port(link: str, port: int) -> int:
    """`port` if it is a TCP port number (0 = any free port), else ValueError naming the link."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= MAX_PORT:
        raise ValueError(f"{link}: port {port!r} is not a TCP port (0..{MAX_PORT}, 0 = any free port)")
    return port


def listen_error(link: str, host: str, port: int | str, exc: BaseException) -> ListenError:
    """The `ListenError` for `exc`, raised while binding `link` to `host`:`port` (port "*": any free port)."""
    reason = bind_reason(exc)
    address = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    error = ListenError(f"cannot listen on {link} {address}: {reason[:1].lower()}{reason[1:]}")
    error.errno = getattr(exc, "errno", None)
    return error


def bind_reason(exc: BaseException) -> str:
    """Why a bind failed, in the system's words (without the address Python and aiohttp add to `strerror`)."""
    number = getattr(exc, "errno", None)
    if not isinstance(exc, socket.gaierror) and number in errno.errorcode:
        return os.strerror(number)
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


def create_server(link: str, host: str, port: int, **options: Any) -> socket.socket:
    """A listening TCP socket on `host`:`port` (`socket.create_server` with `options`); `ListenError` if not."""
    check_port(link, port)
    try:
        return socket.create_server((host, port), **options)
    except OSError as exc:
        raise listen_error(link, host, port, exc) from exc
