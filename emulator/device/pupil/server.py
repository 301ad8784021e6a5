"""The ZeroMQ facade: the virtual tracker as Pupil Capture on the Pupil Core Network API, for unmodified clients.

    server = PupilServer(build_subject(DeviceOptions(scene="guestrin2006")), options=ServerOptions(port=50020))
    with server:                       # tcp://127.0.0.1:50020, Pupil Remote
        print(server.url, server.sub_port, server.pub_port)

Topology (reference/protocols.md section 1; docs/zmq.md): Pupil Remote, a REP socket on `host:port`
(`zmq_remote`), and the IPC backbone (`zmq_backbone`), an XSUB and an XPUB bound on random ports of `host`
relayed on the thread "eyehil-zmq-backbone".
Clients publish to the XSUB (``PUB_PORT``) and subscribe to the XPUB (``SUB_PORT``); the device thread
(`zmq_core`, "eyehil-zmq-publisher"), the frame thread (`zmq_frames`, "eyehil-zmq-frames") and the world
thread (`pupil/world.py`, "eyehil-zmq-world") publish through the backbone too. Everything binds to
127.0.0.1 unless `host` names another interface; so does the LSL outlet (`lsl.outlet`: on the loopback for a
loopback `host`, on every interface otherwise).

Start-up checks the path from Pupil Remote's publisher to the device thread's subscriber (a probe
notification, ``eyehil.ready``, until it arrives) so that no command sent right after start is lost to
ZeroMQ's subscription latency. `close` stops the threads, closes every socket with linger 0 and terminates
the private `zmq.Context`; the server registers itself with `links.register_open` while open.
"""

from __future__ import annotations

import ipaddress
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import zmq

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.clock import Clock, RealTimeClock, make_clock
from eyehil.emulator.device.frames import ExposureRenderer
from eyehil.emulator.device.links.base import register_open, unregister
from eyehil.emulator.device.pupil.backbone import MAX_MESSAGE_BYTES, Backbone, bind, make_socket
from eyehil.emulator.device.pupil.capture import RECORD_MAX_BYTES, Capture
from eyehil.emulator.device.pupil.core import DeviceThread
from eyehil.emulator.device.pupil.datums import PupilTime, eye_windows
from eyehil.emulator.device.pupil.eye3d import EyeModel3d
from eyehil.emulator.device.pupil.frames import FramePublisher
from eyehil.emulator.device.pupil.remote import PupilRemote
from eyehil.emulator.device.pupil.world import MAX_WIDTH_PX, MIN_WIDTH_PX, WORLD_WIDTH_PX, WorldPublisher, WorldView
from eyehil.emulator.device.render_pool import KINDS, MAX_RENDER_WORKERS
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.renderer import DEFAULT_ROI
from eyehil.protocols.native import MAX_RATE_HZ
from eyehil.protocols.pupil import FRAME_FORMATS, notification, pack

READY_TIMEOUT_S = 5.0


@dataclass(frozen=True)
class ServerOptions:
    """Address, rates and the facade's behaviour (units in the names; see docs/zmq.md)."""

    host: str = "127.0.0.1"  # interface to bind; "0.0.0.0" for all
    port: int = 50020  # Pupil Remote; 0 = any free port
    rate_hz: int = 250  # exposures (pupil datums per eye) per second
    frame_rate_hz: float = 30.0  # eye images per second and eye (0: none)
    frame_format: str = "gray"  # until frame_publishing.set_format
    frame_size: tuple[int, int] | None = DEFAULT_ROI  # eye image (w, h) px; None = the full sensor
    settle_s: float = 0.35  # calibration: samples this soon after a target's onset are not used
    hwm: int = 1000  # ZeroMQ high-water marks (messages) of the backbone and the facade's sockets
    seed: int = 0  # image noise
    record_dir: str | None = None  # where `R` writes recording folders (None: none, annotations in memory only)
    record_max_bytes: int = RECORD_MAX_BYTES  # datums all recordings of this facade may write, in total
    lsl: bool = False  # also open an LSL outlet of type Gaze (`lsl.outlet`, needs pylsl); it binds as `host` does
    surface_name: str = "screen"  # the screen's surface topic: surfaces.<name>
    lsl_layout: str = "eyehil"  # or "pupil_relay": Pupil Capture's LSL relay name and channels
    world_rate_hz: float = 30.0  # frame.world images per second (0: none)
    world_width_px: int = WORLD_WIDTH_PX  # frame.world width; the height follows the screen's aspect ratio
    render_workers: int = 0  # eye images rendered in this many processes or threads (0: on the frame thread)
    render_kind: str = "process"  # or "thread" (`render_pool`)

    def __post_init__(self) -> None:
        if not 1 <= self.rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"rate {self.rate_hz} Hz outside 1..{MAX_RATE_HZ}")
        if self.frame_format not in FRAME_FORMATS or not self.frame_rate_hz >= 0 or self.hwm < 1:
            raise ValueError(f"frame format must be one of {FRAME_FORMATS}, frame rate >= 0 and hwm >= 1")
        if self.record_max_bytes < 0:
            raise ValueError("record_max_bytes must be >= 0")
        if not self.world_rate_hz >= 0 or not MIN_WIDTH_PX <= self.world_width_px <= MAX_WIDTH_PX:
            raise ValueError(f"world rate must be >= 0 and world width {MIN_WIDTH_PX}..{MAX_WIDTH_PX} px")
        if not 0 <= self.render_workers <= MAX_RENDER_WORKERS or self.render_kind not in KINDS:
            raise ValueError(f"render workers must be in 0..{MAX_RENDER_WORKERS} and render kind one of {KINDS}")


class PupilServer:
    """The facade; a context manager (see the module docstring). Owns and closes `subject`."""

    def __init__(self, subject: Subject, clock: Clock | None = None, options: ServerOptions | None = None) -> None:
        """Serve `subject` on `clock` (default real time) as `options` say; `start` binds."""
        self.subject, self.clock = subject, clock or RealTimeClock()
        if hasattr(self.clock, "paused"):
            subject.pause_clock = self.clock.paused  # a fast clock's time waits for the subject's exact solves
        self.options = options or ServerOptions()
        self.time = PupilTime(self.clock)
        self.port = self.pub_port = self.sub_port = 0
        self.context: zmq.Context | None = None
        self.outlet = None  # the LSL outlet, with `lsl`
        self.device: DeviceThread | None = None
        self.remote: PupilRemote | None = None
        self._parts: list = []  # things with close(), closed in reverse order

    @property
    def outlet_source_id(self) -> str:
        """The LSL outlet's source id: the same for the same device (scene, eyes, eye anatomy, head, address
        asked for, layout) after a restart (`lsl.outlet.stable_source_id`)."""
        from eyehil.emulator.device.lsl.outlet import stable_source_id

        solver, o = self.subject.solver, self.options
        return stable_source_id(solver.scene.name, solver.scene.sides, repr(solver.eye), solver.head, o.host,
                                o.port, o.lsl_layout)

    @property
    def url(self) -> str:
        """Pupil Remote's address, tcp://host:port."""
        return f"tcp://{self.options.host}:{self.port}"

    def __enter__(self) -> PupilServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- start ------------------------------------------------------------------------------------
    def start(self) -> PupilServer:
        """Bind, check the backbone, start the threads."""
        self.context = zmq.Context()
        try:
            backbone = Backbone(self.context, self.options.host, self.options.hwm)
            self._parts.append(backbone)
            self.pub_port, self.sub_port = backbone.pub_port, backbone.sub_port
            rep = make_socket(self.context, zmq.REP, self.options.hwm)
            rep.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
            self.port = bind(rep, self.options.host, self.options.port)
            remote_pub, device_sub = self._ready_path(backbone.xsub, backbone.xpub)
            self._start_device(backbone.xsub, device_sub)
            self.remote = PupilRemote(rep, remote_pub, self.time, (self.pub_port, self.sub_port))
            self._parts.append(self.remote)
            self.remote.start()
        except BaseException:
            self.close(failed=True)
            raise
        register_open(self, f"zmq {self.url}")
        return self

    def _ready_path(self, xsub: str, xpub: str) -> tuple[zmq.Socket, zmq.Socket]:
        """Pupil Remote's PUB and the device thread's SUB, once a probe has gone from one to the other."""
        hwm = self.options.hwm
        pub, sub = make_socket(self.context, zmq.PUB, hwm), make_socket(self.context, zmq.SUB, hwm)
        pub.connect(xsub)
        sub.setsockopt(zmq.MAXMSGSIZE, MAX_MESSAGE_BYTES)
        sub.connect(xpub)
        for prefix in ("notify.", "annotation"):
            sub.setsockopt_string(zmq.SUBSCRIBE, prefix)
        deadline = time.monotonic() + READY_TIMEOUT_S
        probe = pack(notification("eyehil.ready"))
        while time.monotonic() < deadline:
            pub.send_multipart(probe)
            if sub.poll(10) and sub.recv_multipart()[0] == probe[0]:
                return pub, sub
        raise RuntimeError("the ZeroMQ backbone did not relay a probe within 5 s")

    def _start_device(self, xsub: str, sub: zmq.Socket) -> None:
        o, solver = self.options, self.subject.solver
        eye_ids = tuple(0 if side == "right" else 1 for side in solver.scene.sides)
        windows = eye_windows(solver, eye_ids, o.frame_size)
        frames = None
        if o.frame_rate_hz > 0:
            local = "127.0.0.1" if o.host in ("", "*", "0.0.0.0") else o.host  # render processes connect here
            frames = FramePublisher(self.context, xsub, ExposureRenderer.for_subject(self.subject), windows,
                                    seed=o.seed, hwm=o.hwm, workers=o.render_workers, kind=o.render_kind,
                                    tcp_endpoint=f"tcp://{local}:{self.pub_port}")
            self._parts.append(frames)
        world = None
        if o.world_rate_hz > 0:
            world = WorldPublisher(self.context, xsub, WorldView.of_screen(solver.scene.screen.size, o.world_width_px),
                                   hwm=o.hwm)
            self._parts.append(world)
        if o.lsl:
            import numpy as np

            from eyehil.emulator.device.lsl.outlet import GazeOutlet

            scene = solver.scene
            self.outlet = GazeOutlet(windows, len(scene.leds), o.rate_hz, self.clock, name="eyehil",
                                     source_id=self.outlet_source_id, layout=o.lsl_layout,
                                     screen=(scene.screen.centre, scene.screen.size),
                                     pupil_mm=2.0 * float(np.asarray(solver.eye.pupil_radius).reshape(-1)[0]),
                                     eye_centres=EyeModel3d.of(solver).centres,
                                     bind="loopback" if loopback(o.host) else "all")
            self._parts.append(self.outlet)
        capture = Capture(solver.scene, eye_ids, self.time, lambda xy, t_us: device.show(xy, t_us),
                          settle_s=o.settle_s, frame_format=o.frame_format, record_dir=o.record_dir,
                          record_max_bytes=o.record_max_bytes)
        device = DeviceThread(self.context, xsub, sub, self.subject, self.clock, self.time, windows, capture,
                              rate_hz=o.rate_hz, frames=frames, outlet=self.outlet, hwm=o.hwm,
                              frame_every=max(1, round(o.rate_hz / o.frame_rate_hz)) if frames else 1,
                              surface_name=o.surface_name, world=world,
                              world_every=max(1, round(o.rate_hz / o.world_rate_hz)) if world else 1)
        self._parts.append(device.capture)
        self._parts.append(device)
        self.device = device
        for part in (frames, world):
            if part is not None:
                part.start()
        device.start()

    # --- state and close --------------------------------------------------------------------------
    def wait_until(self, condition: Callable[[], bool], timeout_s: float | None = None) -> bool:
        """Wait until `condition()` (on what the device thread changes: `counters`, `annotations`, the outlet)
        holds, re-checked after each turn of the device thread's loop (each batch of messages or exposures, at
        least every `core.IDLE_S`); False at the timeout. For tests and tools: no polling with sleeps."""
        stepped = self.device.stepped
        with stepped:
            return stepped.wait_for(condition, timeout_s)

    @property
    def counters(self) -> Counter[str]:
        """What the facade counted: requests, messages, exposures, drops (docs/zmq.md; 0 if never); any thread."""
        out: Counter[str] = Counter()
        for _ in range(100):  # the threads may add a key while we copy
            try:
                out = Counter({k: v for part in self._parts for k, v in getattr(part, "counters", {}).items()})
                break
            except RuntimeError:
                continue
        frames = next((p for p in self._parts if isinstance(p, FramePublisher)), None)
        if frames is not None:
            out.update(frames_published=frames.published, frames_dropped=frames.dropped)
        world = next((p for p in self._parts if isinstance(p, WorldPublisher)), None)
        if world is not None:
            out.update(world_published=world.published, world_dropped=world.dropped)
        return out

    @property
    def annotations(self) -> list[dict]:
        """The annotations received (the latest `zmq_capture.MAX_ANNOTATIONS`)."""
        return self.device.capture.annotations

    def close(self, failed: bool = False) -> None:
        """Stop every thread, close every socket, terminate the context, release the subject; idempotent.
        `failed`: a start went wrong, sockets not yet handed to a thread are closed with the context."""
        while self._parts:
            self._parts.pop().close()
        if self.context is not None:
            if failed:
                self.context.destroy(linger=0)
            else:
                self.context.term()
            self.context = None
            self.subject.close()
        unregister(self)


def loopback(host: str) -> bool:
    """`host` (an interface to bind) reaches this machine only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # "", "*", a host name
        return False


def server_for(options: DeviceOptions, host: str = "127.0.0.1", port: int = 50020, *, lsl: bool = False,
               **server: object) -> PupilServer:
    """An unstarted facade for device `options` (`eyehil emulate --link zmq`): its subject, clock, rate and seed;
    `server`: more `ServerOptions` fields."""
    if options.mode != "native":
        raise ValueError("--link zmq emulates Pupil Capture: no ISCAN mode")
    if lsl:
        from eyehil.emulator.device.lsl.library import LslUnavailableError, load_pylsl

        try:
            load_pylsl()
        except LslUnavailableError as exc:
            raise ValueError(str(exc)) from exc
    server.setdefault("render_workers", options.render_workers)
    opts = ServerOptions(host=host, port=port, rate_hz=options.rate_hz, seed=options.seed, lsl=lsl, **server)
    return PupilServer(build_subject(options), make_clock(options.clock, options.speed), opts)
