"""Addresses the links listen on and connect to: TCP port numbers, checked the same way by every command.

`port_number("4242") -> 4242`; a port outside 0..65535 (0: any free port) or not a number raises
`PortNumberError`, which is a ValueError for library callers and an argparse.ArgumentTypeError, so a command
line that passes `type=port_number` prints the message as its usage error (exit 2).
"""

from __future__ import annotations

import argparse

MAX_PORT = 65535


class PortNumberError(ValueError, argparse.ArgumentTypeError):
    """Not a TCP port number; the message says why."""


def port_number(text: str | int) -> int:
    """A TCP port, 0..65535 (0: any free port), from text or an int."""
    try:
        port = int(text)
    except ValueError:
        raise PortNumberError(f"{text!r} is not a port number") from None
    if not 0 <= port <= MAX_PORT:
        raise PortNumberError(f"{port} is not a TCP port (0..{MAX_PORT}, 0 = any free port)")
    return port
