"""The Open Gaze API server: the virtual tracker as a Gazepoint GP3 on TCP (port 4242), for unmodified clients.

    with OpenGazeServer(build_subject(DeviceOptions(sides="both")), options=ServerOptions(port=0)) as server:
        print(server.url)                   # tcp://127.0.0.1:<port>
        server.show((0.3, 0.7))             # the subject looks there (screen fractions, top-left origin)

One thread ("eyehil-opengaze") owns the listening socket, every client socket (non-blocking, `selectors`) and
the device core (`opengaze.core.OpenGazeDevice`). It wakes at each exposure's time and whenever a socket is
ready. Limits (docs/opengaze.md), each counted in `counters`:

- at most `MAX_CLIENTS` clients (more are accepted and closed at once: ``clients_refused``);
- per client, input is read in chunks of `READ_BYTES`, cut into lines of at most
  `eyehil.protocols.opengaze.MAX_LINE_BYTES` (longer lines get ``NACK ERROR="TOO_LONG"`` and are skipped), and at
  most `MAX_RECORDS_PER_WAKE` records are answered per wake-up (the rest wait in the client's buffer,
  which holds at most `MAX_PENDING_LINES` lines: a client that floods is disconnected,
  ``clients_dropped``);
- per client, output waiting for the socket is bounded: REC records beyond `MAX_OUT_BYTES` are dropped
  (``records_dropped``); a client whose answers (ACK, NACK, CAL) would exceed `2 * MAX_OUT_BYTES` is
  disconnected (``clients_dropped``).

Everything binds to 127.0.0.1 unless `host` names another interface; the server prints nothing itself (the
command line prints the URL).
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import socket
import threading
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.clock import Clock, RealTimeClock, make_clock
from eyehil.emulator.device.links.base import register_open, unregister
from eyehil.emulator.device.links.listen import create_server
from eyehil.emulator.device.opengaze.calibration import DEFAULT_POINTS
from eyehil.emulator.device.opengaze.core import OpenGazeDevice, OpenGazeOptions, Out
from eyehil.emulator.device.opengaze.samples import fraction_to_screen
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.opengaze import PORT, LineSplitter

MAX_CLIENTS = 16
READ_BYTES = 65536
MAX_RECORDS_PER_WAKE = 256
MAX_PENDING_LINES = 4096
MAX_OUT_BYTES = 1 << 20


@dataclass(frozen=True)
class ServerOptions:
    """Address and the device's behaviour."""

    host: str = "127.0.0.1"
    port: int = PORT  # 0 = any free port
    device: OpenGazeOptions = field(default_factory=OpenGazeOptions)


class _Client:
    """One connection: its socket, line splitter, pending lines and output."""

    def __init__(self, sock: socket.socket, cid: int) -> None:
        self.sock, self.cid = sock, cid
        self.lines = LineSplitter()
        self.pending: deque = deque()
        self.out = bytearray()


class OpenGazeServer:
    """See the module docstring. Owns and closes `subject`."""

    def __init__(self, subject: Subject, clock: Clock | None = None, options: ServerOptions | None = None) -> None:
        self.subject, self.clock = subject, clock or RealTimeClock()
        self.options = options or ServerOptions()
        self.device: OpenGazeDevice | None = None
        self.port = 0
        self.counters: Counter[str] = Counter()
        self.failure: Exception | None = None
        self._listener: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        self._clients: dict[socket.socket, _Client] = {}
        self._stop = threading.Event()
        self._lock = threading.Lock()  # `show` from other threads
        self._shows: deque[tuple[float, float]] = deque(maxlen=16)
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """tcp://host:port."""
        return f"tcp://{self.options.host}:{self.port}"

    def __enter__(self) -> OpenGazeServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> OpenGazeServer:
        """Bind and listen (an address in use fails at once, `ListenError`), solve ahead what the default
        calibration needs (a few seconds; a host that connects meanwhile waits in the backlog), start the thread."""
        listener = create_server("opengaze", self.options.host, self.options.port, reuse_port=False, backlog=16)
        try:
            self._warm_up()
            self.device = OpenGazeDevice(self.subject, self.clock, self.options.device)
        except BaseException:
            listener.close()
            raise
        listener.setblocking(False)
        self._listener, self.port = listener, listener.getsockname()[1]
        self._selector = selectors.DefaultSelector()
        self._selector.register(listener, selectors.EVENT_READ)
        self._thread = threading.Thread(target=self._run, name="eyehil-opengaze", daemon=True)
        self._thread.start()
        register_open(self, f"opengaze {self.url}")
        return self

    def _warm_up(self) -> None:
        """Build the solver's interpolation grid and solve the default calibration points now, so that the
        streaming thread never waits for them (saccades are interpolated in the grid)."""
        solver = self.subject.solver
        solver.field  # noqa: B018 - built once
        solver.exact(fraction_to_screen(solver.scene.screen.size, np.array(DEFAULT_POINTS)))

    def show(self, xy: tuple[float, float]) -> None:
        """The subject looks at screen fractions `xy` (top-left origin) from now; any thread."""
        with self._lock:
            self._shows.append((float(xy[0]), float(xy[1])))

    @property
    def all_counters(self) -> Counter[str]:
        """The server's and the device's counters."""
        out = Counter(self.counters)
        if self.device is not None:
            out.update(dict(self.device.counters))
        return out

    # --- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                for key, events in self._selector.select(self.device.wait_s()):
                    if key.fileobj is self._listener:
                        self._accept()
                    elif key.fileobj in self._clients:
                        self._io(self._clients[key.fileobj], events)
                with self._lock:
                    shows, self._shows = list(self._shows), deque(maxlen=16)
                for xy in shows:
                    self.device.show(xy)
                for client in list(self._clients.values()):
                    self._answer(client)
                self._deliver(self.device.step())
        except Exception as exc:  # a bug: stop loudly rather than hang the clients
            self.failure = exc
            logging.getLogger(__name__).exception("the Open Gaze server thread stopped")
        finally:
            for client in list(self._clients.values()):
                self._drop(client, counted=False)

    def _accept(self) -> None:
        try:
            sock, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        if len(self._clients) >= MAX_CLIENTS:
            self.counters["clients_refused"] += 1
            sock.close()
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock, self.device.connect())
        self._clients[sock] = client
        self._selector.register(sock, selectors.EVENT_READ)
        self.counters["clients"] += 1

    def _io(self, client: _Client, events: int) -> None:
        if events & selectors.EVENT_WRITE:
            self._flush(client)
        if events & selectors.EVENT_READ and client.sock in self._clients:
            try:
                data = client.sock.recv(READ_BYTES)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._drop(client, counted=False)
                return
            client.pending.extend(client.lines.feed(data))
            if len(client.pending) > MAX_PENDING_LINES:
                self._drop(client)

    def _answer(self, client: _Client) -> None:
        for _ in range(min(MAX_RECORDS_PER_WAKE, len(client.pending))):
            self._deliver(self.device.handle(client.cid, client.pending.popleft()))
            if client.sock not in self._clients:
                return

    def _deliver(self, outs: list[Out]) -> None:
        by_cid = {c.cid: c for c in self._clients.values()}
        touched = set()
        for out in outs:
            targets = by_cid.values() if out.cid is None else [by_cid[out.cid]] if out.cid in by_cid else []
            for client in targets:
                if client.sock not in self._clients:
                    continue
                if out.droppable and len(client.out) >= MAX_OUT_BYTES:
                    self.counters["records_dropped"] += 1
                    continue
                if len(client.out) + len(out.data) > 2 * MAX_OUT_BYTES:
                    self._drop(client)
                    continue
                client.out += out.data
                touched.add(client.sock)
        for sock in touched:
            if sock in self._clients:
                self._flush(self._clients[sock])

    def _flush(self, client: _Client) -> None:
        try:
            sent = client.sock.send(client.out) if client.out else 0
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError:
            self._drop(client, counted=False)
            return
        del client.out[:sent]
        want = selectors.EVENT_READ | (selectors.EVENT_WRITE if client.out else 0)
        self._selector.modify(client.sock, want)

    def _drop(self, client: _Client, counted: bool = True) -> None:
        if counted:
            self.counters["clients_dropped"] += 1
        self._clients.pop(client.sock, None)
        self.device.disconnect(client.cid)
        with contextlib.suppress(KeyError, ValueError):
            self._selector.unregister(client.sock)
        client.sock.close()

    # --- close -------------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the thread, close every socket, release the subject; idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._listener is not None:
            self._selector.close()
            self._listener.close()
            self._listener = None
            self.device.close()
            self.subject.close()
        unregister(self)


def server_for(options: DeviceOptions, host: str = "127.0.0.1", port: int = PORT, **device: object
               ) -> OpenGazeServer:
    """An unstarted server for device `options` (`eyehil emulate --link opengaze`): both eyes unless `sides`
    says otherwise, the device's rate; `device`: more `OpenGazeOptions` fields."""
    if options.mode != "native":
        raise ValueError("--link opengaze emulates a Gazepoint tracker: no ISCAN mode")
    if not options.sides:
        from dataclasses import replace

        options = replace(options, sides="both")
    opts = ServerOptions(host=host, port=port, device=OpenGazeOptions(rate_hz=options.rate_hz, **device))
    return OpenGazeServer(build_subject(options, appearance=False), make_clock(options.clock, options.speed), opts)
