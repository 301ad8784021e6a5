"""Helpers of the ZeroMQ facade tests: start a facade, wait for messages (no sleeps), pair subscriptions."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pupil_labs.pupil_core_network_client import Device

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.clock import make_clock
from eyehil.emulator.device.pupil.server import PupilServer, ServerOptions
from eyehil.emulator.device.subject import Behaviour

_DEVICE_KEYS = {"scene", "eyes", "eye", "sides", "seed"}


def start_server(latency: float = 0.05, clock: str = "real", **options: Any) -> PupilServer:
    """A started facade on a free port: `DeviceOptions` keys (scene, eyes, eye, sides, seed), the subject's
    saccadic `latency` (s), the `clock` ("fast": device time waits for the subject's exact fixation solves, so
    what it streams does not depend on how busy the machine is) and `ServerOptions` fields."""
    device = {k: options.pop(k) for k in list(options) if k in _DEVICE_KEYS}
    subject = build_subject(DeviceOptions(behaviour=Behaviour(latency_s=latency), clock=clock, **device))
    return PupilServer(subject, make_clock(clock), options=ServerOptions(**{"port": 0, **options})).start()


GENEROUS_S = 120.0  # bounds a wait for the facade's threads (a calibration fit takes seconds of CPU; a busy
# machine gives this process a fraction of a core): only a hang reaches it


def wait_for(sub, accept: Callable[[Any], bool], timeout_s: float = GENEROUS_S) -> Any:
    """The first message of the client subscription `sub` that `accept`s, or AssertionError at the timeout."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = sub.recv_new_message(timeout_ms=100)
        if message is not None and accept(message):
            return message
    raise AssertionError(f"no accepted message within {timeout_s} s")


def topic_is(topic: str) -> Callable[[Any], bool]:
    return lambda m: m.topic == topic


def subscribed(device: Device, sub, timeout_s: float = 10.0) -> None:
    """Return once `sub` (which must subscribe to ``notify.``) receives what `device` sends: ZeroMQ
    subscriptions take effect a little after connecting."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        device.send_notification({"subject": "test.hello"})
        message = sub.recv_new_message(timeout_ms=50)
        while message is not None:
            if message.topic == "notify.test.hello":
                return
            message = sub.recv_new_message(timeout_ms=0)
    raise AssertionError("the subscription never received a notification")


def eventually(srv: PupilServer, condition: Callable[[], bool], timeout_s: float = GENEROUS_S) -> None:
    """Wait until `condition` (on what `srv`'s device thread changes) holds, re-checked each time that thread
    completes a turn (an explicit event, no sleeps), or AssertionError at the timeout."""
    if not srv.wait_until(condition, timeout_s):
        raise AssertionError(f"condition not met within {timeout_s} s")
