"""Pupil Remote: the REQ/REP command socket of the ZeroMQ facade, on its own thread ("eyehil-zmq-remote").

Every request gets exactly one reply (`eyehil.protocols.pupil` lists them); what a request sets off goes out on the
backbone through this thread's own PUB (connected to the XSUB), where the device thread receives it like
any client's notification:

| request | reply | published |
|---|---|---|
| multipart (topic, payload, raw frames...) | ``Message forwarded.`` | the message, payload `topic` := frame 0 |
| ``SUB_PORT`` / ``PUB_PORT`` | the XPUB / XSUB port | |
| ``R [name]`` / ``r`` | ``OK`` | ``notify.recording.should_start {session_name}`` / ``should_stop`` |
| ``C`` / ``c`` | ``OK`` | ``notify.calibration.should_start`` / ``should_stop`` |
| ``T <float>`` | ``Timesync successful.`` | (Pupil time := the float, now) |
| ``t`` | ``repr`` of Pupil time (s) | |
| ``v`` | `eyehil.protocols.pupil.VERSION` | |
| anything else, or not UTF-8 | ``Unknown command.`` | |

A multipart message that `eyehil.protocols.pupil.unpack` refuses (bad msgpack, non-string keys, too deep, too big,
topic not UTF-8) is answered ``Malformed message: <reason>`` and not forwarded; a message larger than
`zmq_backbone.MAX_MESSAGE_BYTES` makes libzmq drop that client's connection. Either way the REP socket goes
on serving the other clients.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Sequence

import zmq

from eyehil.emulator.device.pupil.datums import PupilTime
from eyehil.protocols.pupil import (
    REPLY_FORWARDED,
    REPLY_MALFORMED,
    REPLY_OK,
    REPLY_TIMESYNC,
    REPLY_UNKNOWN,
    VERSION,
    PupilMessageError,
    notification,
    pack,
    parse_request,
    unpack,
)

POLL_MS = 100

_NOTIFY = {"record_stop": "recording.should_stop", "calibration_start": "calibration.should_start",
           "calibration_stop": "calibration.should_stop"}


class PupilRemote:
    """Answers Pupil Remote requests; see the module docstring."""

    def __init__(self, rep: zmq.Socket, pub: zmq.Socket, time: PupilTime, ports: tuple[int, int]) -> None:
        """`rep`: the bound REP socket; `pub`: a PUB connected to the XSUB; `ports`: (XSUB, XPUB)."""
        self.rep, self.pub, self.time = rep, pub, time
        self.pub_port, self.sub_port = ports
        self.counters: Counter[str] = Counter()
        self.failure: Exception | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="eyehil-zmq-remote", daemon=True)

    def answer(self, frames: Sequence[bytes]) -> str:
        """The reply to one request; publishes what the request sets off."""
        self.counters["requests"] += 1
        request = parse_request(frames)
        kind = request.kind
        if kind == "forward":
            return self._forward(frames)
        if kind in ("sub_port", "pub_port"):
            return str(self.sub_port if kind == "sub_port" else self.pub_port)
        if kind == "record_start":
            self._notify("recording.should_start", session_name=request.argument or "")
        elif kind in _NOTIFY:
            self._notify(_NOTIFY[kind])
        elif kind == "time_sync":
            self.time.set_now(request.argument)
            return REPLY_TIMESYNC
        elif kind == "time_query":
            return repr(self.time.now())
        elif kind == "version":
            return VERSION
        else:
            self.counters["unknown"] += 1
            return REPLY_UNKNOWN
        return REPLY_OK

    def _forward(self, frames: Sequence[bytes]) -> str:
        try:
            topic, payload = unpack(frames)
            message = pack({**payload, "topic": topic})
        except PupilMessageError as exc:
            self.counters["malformed"] += 1
            return REPLY_MALFORMED + str(exc)
        self.pub.send_multipart(message, copy=len(message) < 3)
        return REPLY_FORWARDED

    def _notify(self, subject: str, **fields: object) -> None:
        self.pub.send_multipart(pack(notification(subject, **fields)))

    # --- the thread ---------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                if self.rep.poll(POLL_MS):
                    self.rep.send_string(self.answer(self.rep.recv_multipart()))
        except Exception as exc:  # a bug: stop loudly rather than leave clients hanging forever
            self.failure = exc
            logging.getLogger(__name__).exception("Pupil Remote stopped")
        finally:
            self.rep.close(linger=0)
            self.pub.close(linger=0)

    def close(self) -> None:
        """Stop and join the thread (it closes its sockets)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        elif not self.rep.closed:
            self.rep.close(linger=0)
            self.pub.close(linger=0)
