"""Wait for a stop in a command's main thread, noticing SIGTERM and Ctrl-C promptly.

A command installs a SIGTERM handler that sets a `threading.Event` and then waits on that event. CPython runs
Python signal handlers in the main thread only, and only once it executes bytecode again; the C-level signal is
delivered by the kernel to any thread that does not block it. When it lands on a worker thread (a renderer, a
publisher: likely when they are busy), a main thread blocked in one long `Event.wait` is not woken, and the
command lingers until the wait ends (seen: `eyehil emulate --link zmq` ignored SIGTERM for its whole
`--duration`, once in 30 runs beside four busy processes). `wait_for_stop` waits in slices of `SLICE_S`, so
the handler runs within one slice. Shared by the layers (emulator, drivers): it imports no eyehil module.
"""

from __future__ import annotations

import threading
import time

SLICE_S = 0.25  # the longest a SIGTERM or Ctrl-C waits to be noticed


def wait_for_stop(stop: threading.Event, duration: float | None = None) -> bool:
    """Block until `stop` is set (True) or `duration` s pass (False; None: no limit), waking every `SLICE_S`."""
    deadline = None if duration is None else time.monotonic() + duration
    while not stop.is_set():
        remaining = SLICE_S if deadline is None else min(SLICE_S, deadline - time.monotonic())
        if remaining <= 0:
            return False
        stop.wait(remaining)
    return True
