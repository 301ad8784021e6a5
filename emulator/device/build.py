"""Build a virtual device from a few named options (command line, loop:// URLs, the pytest plugin).

`DeviceOptions` names everything a device needs: the scene (camera, LEDs, screen, which eyes; `sides`
overrides the eyes), the eye anatomy (an `eyehil.emulator.eye.select` spec and an index into it), the head
pose, the behaviour, the script (`"stimulus"`: follow the host's STIMULUS messages; `"demo"`: loop over
the scene's targets with saccades, a pursuit and blinks), the mode (native or ISCAN), the default rate
and the clock. A native device also streams frames (`frame_stream`): its subject's solver carries the
appearance channels (`appearance.AppearanceSolver`), and the image noise is a function of
`seed`, the frame id and the eye (`frames.exposure_noise`).

URL form (loop://, and `--option` values): ``scene=blignaut2014&eyes=published&eye=3&clock=fast&rate=500``.
``link_rate=usb-fs`` paces a native link (pty, tcp, usbip) to a real link's byte rate (`links.paced`);
``render_workers=2`` renders frames in two processes ahead of the link (`render_pool`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from urllib.parse import parse_qsl

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver
from eyehil.emulator.device.clock import make_clock
from eyehil.emulator.device.frame_stream import FrameOptions
from eyehil.emulator.device.gaze import Blink, Fixation, Pursuit, Segment
from eyehil.emulator.device.iscan import IscanTracker
from eyehil.emulator.device.links.paced import parse_link_rate
from eyehil.emulator.device.render_pool import MAX_RENDER_WORKERS
from eyehil.emulator.device.solve_process import ProcessSolves
from eyehil.emulator.device.solver import FeatureSolver, InThreadSolves, tracked_scene
from eyehil.emulator.device.subject import Behaviour, Subject
from eyehil.emulator.device.tracker import VirtualTracker
from eyehil.emulator.eye.select import eyes_from_spec
from eyehil.emulator.scene import HeadPose, Scene, load_scene


@dataclass(frozen=True)
class DeviceOptions:
    """Everything that defines a virtual device; see the module docstring."""

    scene: str = "guestrin2006"  # preset name or TOML path
    eyes: str = "normative:navarro"  # eyehil.emulator.eye.select spec
    eye: int = 0  # which eye of the spec (both of the subject's eyes share this anatomy)
    sides: str = ""  # eyes the camera sees: "right", "left", "both"; "" = the scene's own
    seed: int = 0  # for sampled eyes and the subject's random behaviour
    head: HeadPose = field(default_factory=HeadPose)
    behaviour: Behaviour = field(default_factory=Behaviour)
    script: str = "stimulus"  # or "demo"
    mode: str = "native"  # or "iscan"
    rate_hz: int = 250  # default rate (native) or the fixed rate (ISCAN)
    clock: str = "real"  # or "fast"
    speed: float = 1.0  # real clock: device seconds per wall second
    link_rate: str = ""  # pace the native link's output, e.g. "12Mbit", "115200baud", "usb-fs" ("": unpaced)
    render_workers: int = 0  # frames: render in this many processes, ahead of the link (0: on the device's thread)
    solves: str = "auto"  # where fixation solves run: "process", "thread"; auto: process on the real clock

    def __post_init__(self) -> None:
        if self.link_rate:
            parse_link_rate(self.link_rate)  # raises ValueError with the accepted forms
        if not 0 <= self.render_workers <= MAX_RENDER_WORKERS:
            raise ValueError(f"render_workers must be in 0..{MAX_RENDER_WORKERS}, got {self.render_workers}")
        if self.script not in ("stimulus", "demo"):
            raise ValueError(f"script must be 'stimulus' or 'demo', got {self.script!r}")
        if self.sides not in ("", "right", "left", "both"):
            raise ValueError(f"sides must be 'right', 'left' or 'both', got {self.sides!r}")
        if self.mode not in ("native", "iscan"):
            raise ValueError(f"mode must be 'native' or 'iscan', got {self.mode!r}")
        if self.solves not in ("auto", "process", "thread"):
            raise ValueError(f"solves must be 'auto', 'process' or 'thread', got {self.solves!r}")


def demo_script(scene: Scene) -> list[Segment]:
    """Fixations (0.8 s) on up to 3 x 3 of the scene's targets, a blink every third, a pursuit across the screen."""
    cols, rows = scene.screen.grid
    grid = scene.targets().reshape(cols, rows, 3)
    pick_c, pick_r = np.unique(np.linspace(0, cols - 1, 3).round()), np.unique(np.linspace(0, rows - 1, 3).round())
    points = [tuple(scene.screen.to_screen(grid[int(c), int(r)])) for r in pick_r for c in pick_c]
    script: list[Segment] = []
    for i, p in enumerate(points):
        script.append(Fixation((float(p[0]), float(p[1])), 0.8))
        if i % 3 == 2:
            script.append(Blink(0.15))
    width = scene.screen.size[0]
    script += [Fixation((0.4 * width, 0.0), 0.3), Pursuit((-0.4 * width, 0.0), 10.0), Fixation((0.0, 0.0), 0.5)]
    return script


FAST_CLOCK_SOLVE_WAIT_S = 5.0  # fast clock (virtual time): how long an observation may wait for an exact solve


def build_subject(options: DeviceOptions, appearance: bool = True) -> Subject:
    """The simulated subject of `options`; with `appearance`, its observations also carry what frames are drawn
    from (`appearance.AppearanceSolver`). On the real clock the subject never waits for a solve (fixations of new
    targets are interpolated until solved); on the fast clock, whose time is virtual, it waits for the exact one
    (at most `FAST_CLOCK_SOLVE_WAIT_S`). The solves of new targets run in a worker process on the real clock (they
    would otherwise hold the GIL the streaming thread needs: `solve_process`) and on a thread of this process on
    the fast clock, whose device waits for them anyway (a process would only add its start-up); `options.solves`
    overrides."""
    scene = load_scene(options.scene)
    if options.sides:
        scene = tracked_scene(scene, ("right", "left") if options.sides == "both" else (options.sides,))
    eyes, _ = eyes_from_spec(options.eyes, options.seed)
    if not 0 <= options.eye < len(eyes):
        raise ValueError(f"eye {options.eye} out of range: the spec {options.eyes!r} gives {len(eyes)} eye(s)")
    solver = (AppearanceSolver if appearance else FeatureSolver)(eyes[options.eye], scene, options.head)
    script = demo_script(scene) if options.script == "demo" else None
    wait_s = FAST_CLOCK_SOLVE_WAIT_S if options.clock == "fast" else 0.0
    where = options.solves if options.solves != "auto" else "thread" if options.clock == "fast" else "process"
    return Subject(solver, options.behaviour, rng=np.random.default_rng(options.seed), script=script,
                   exact_wait_s=wait_s, solves=ProcessSolves if where == "process" else InThreadSolves)


def build_device(options: DeviceOptions | None = None) -> VirtualTracker | IscanTracker:
    """A device core (native `VirtualTracker` or `IscanTracker`) as `options` say."""
    options = options or DeviceOptions()
    clock = make_clock(options.clock, options.speed, lockstep=True)  # the runner or loop port pushes time
    subject = build_subject(options, appearance=options.mode == "native")
    if options.mode == "iscan":
        return IscanTracker(subject, clock, rate_hz=options.rate_hz)
    return VirtualTracker(subject, clock, default_rate_hz=options.rate_hz,
                          frames=FrameOptions(seed=options.seed, workers=options.render_workers))


def paced(link, options: DeviceOptions, clock):
    """`link` paced to `options.link_rate` on the device's `clock` (`links.paced.PacedLink`), or `link` itself."""
    if not options.link_rate:
        return link
    from eyehil.emulator.device.links.paced import PacedLink

    return PacedLink(link, parse_link_rate(options.link_rate), clock)


_HEAD_KEYS = ("x", "y", "z", "yaw", "pitch", "roll")
_BEHAVIOUR_KEYS = {"latency": "latency_s", "latency_sd": "latency_sd_s", "jitter": "jitter_deg",
                   "blinks": "blink_rate_hz", "blink_s": "blink_s"}


def options_from_query(query: str, base: DeviceOptions | None = None) -> DeviceOptions:
    """`base` (default options) updated from ``key=value&...``; keys: the fields of `DeviceOptions` (rate for
    rate_hz), head x, y, z, yaw, pitch, roll (mm, deg) and behaviour latency, latency_sd, jitter, blinks, blink_s."""
    base = base or DeviceOptions()
    names = {f.name: f for f in fields(DeviceOptions)} | {"rate": next(f for f in fields(DeviceOptions)
                                                                      if f.name == "rate_hz")}
    plain, head, behaviour = {}, {}, {}
    for key, value in parse_qsl(query, keep_blank_values=True, strict_parsing=bool(query)):
        if key in _HEAD_KEYS:
            head[key] = float(value)
        elif key in _BEHAVIOUR_KEYS:
            behaviour[_BEHAVIOUR_KEYS[key]] = float(value)
        elif key in names and key not in ("head", "behaviour"):
            f = names[key]
            plain[f.name] = {"int": int, "float": float}.get(str(f.type), str)(value)
        else:
            raise ValueError(f"unknown device option {key!r}")
    return replace(base, head=replace(base.head, **head), behaviour=replace(base.behaviour, **behaviour), **plain)
