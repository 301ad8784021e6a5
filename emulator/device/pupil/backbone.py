"""The IPC backbone of the ZeroMQ facade: an XSUB and an XPUB relayed by `zmq.proxy_steerable`.

Both sockets bind to random TCP ports of the host (the ports Pupil Remote's ``PUB_PORT`` and ``SUB_PORT``
answer: clients publish to the XSUB, subscribe to the XPUB) and to inproc endpoints for the facade's own
sockets. The relay runs on the thread "eyehil-zmq-backbone" until `close` sends ``TERMINATE`` on the
proxy's control socket; the thread then closes the three sockets. A message over `MAX_MESSAGE_BYTES` makes
libzmq drop its sender's connection.
"""

from __future__ import annotations

import threading

import zmq

from eyehil.emulator.device.links.listen import check_port, listen_error

MAX_MESSAGE_BYTES = 32 * 1024 * 1024


def make_socket(context: zmq.Context, kind: int, hwm: int) -> zmq.Socket:
    """A socket with linger 0 and both high-water marks at `hwm` messages."""
    sock = context.socket(kind)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.SNDHWM, hwm)
    sock.setsockopt(zmq.RCVHWM, hwm)
    return sock


def bind(sock: zmq.Socket, host: str, port: int = 0) -> int:
    """Bind `sock` to tcp://host:port (port 0: any free port); return the port. `ListenError` (naming the link
    "zmq" and the address) if it cannot; ValueError for a port out of 0..65535 (libzmq would wrap it around)."""
    check_port("zmq", port)
    try:
        if port:
            sock.bind(f"tcp://{host}:{port}")
            return port
        return sock.bind_to_random_port(f"tcp://{host}")
    except zmq.ZMQError as exc:
        raise listen_error("zmq", host, port or "*", exc) from exc


class Backbone:
    """The XSUB / XPUB pair and its relay; see the module docstring."""

    def __init__(self, context: zmq.Context, host: str, hwm: int) -> None:
        """Bind both sockets and start relaying."""
        xsub, xpub = make_socket(context, zmq.XSUB, hwm), make_socket(context, zmq.XPUB, hwm)
        xsub.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        self.pub_port, self.sub_port = bind(xsub, host), bind(xpub, host)
        name = f"inproc://eyehil-{id(self):x}"
        self.xsub, self.xpub = f"{name}-xsub", f"{name}-xpub"  # inproc endpoints for the facade's sockets
        xsub.bind(self.xsub)
        xpub.bind(self.xpub)
        self._control = context.socket(zmq.PAIR)
        self._control.bind(f"{name}-control")
        steer = context.socket(zmq.PAIR)
        steer.connect(f"{name}-control")
        self._thread = threading.Thread(target=_relay, args=(xsub, xpub, steer), name="eyehil-zmq-backbone",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the relay and close its sockets; idempotent."""
        if self._control is None:
            return
        self._control.send(b"TERMINATE")
        self._thread.join()
        self._control.close(linger=0)
        self._control = None


def _relay(xsub: zmq.Socket, xpub: zmq.Socket, control: zmq.Socket) -> None:
    """The backbone's thread: relay until TERMINATE arrives on `control`, then close the three sockets."""
    try:
        zmq.proxy_steerable(xsub, xpub, None, control)
    except zmq.ContextTerminated:
        pass
    finally:
        for sock in (xsub, xpub, control):
            sock.close(linger=0)
