"""`eyehil.stopping.wait_for_stop`: a SIGTERM that lands on another thread still ends a command's wait."""

from __future__ import annotations

import signal
import threading

from eyehil.stopping import wait_for_stop


def test_sigterm_delivered_to_a_worker_thread_ends_the_wait() -> None:
    """The worker thread takes the signal (pthread_kill); the main thread, blocked in `wait_for_stop` without a
    duration, runs the handler within a slice and returns True. A single `Event.wait()` would block for ever
    (not tried here, for that reason)."""
    stop, worker_ready, done = threading.Event(), threading.Event(), threading.Event()
    worker: list[int] = []

    def busy() -> None:
        worker.append(threading.get_ident())
        worker_ready.set()
        done.wait()

    thread = threading.Thread(target=busy, daemon=True)
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        thread.start()
        assert worker_ready.wait(30)
        killer = threading.Timer(0.05, signal.pthread_kill, (worker[0], signal.SIGTERM))
        killer.start()
        assert wait_for_stop(stop) is True
    finally:
        done.set()
        thread.join(30)
        signal.signal(signal.SIGTERM, previous)


def test_the_duration_ends_the_wait_without_a_stop() -> None:
    assert wait_for_stop(threading.Event(), 0.01) is False
    stop = threading.Event()
    stop.set()
    assert wait_for_stop(stop, 60) is True
