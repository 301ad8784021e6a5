"""The Open Gaze device core: client records in, ACK / NACK / REC / CAL records out; no sockets, no threads.

The server (`opengaze.server`) owns one `OpenGazeDevice` and calls it from its one thread:

    cid = device.connect()                      # a client arrived
    outs = device.handle(cid, line)             # one line from it (bytes, or eyehil.protocols.opengaze.OVERLONG)
    outs = device.step()                        # exposures and calibration events due now
    device.disconnect(cid)

Each output is an `Out`: the client it is for (None: every client), the encoded record and whether it may
be dropped when that client's queue is full (REC records) or not (ACK, NACK, CAL).

State: the data switches (ENABLE_SEND_*, ENABLE_SEND_DATA) belong to each client; the calibration (points,
DELAY, TIMEOUT, the running calibration and its result), SCREEN_SIZE, USER_DATA and the display switches
belong to the device, as on a tracker shared by its clients. The camera exposes at `rate_hz` from the
start; REC records go to the clients whose ENABLE_SEND_DATA is on, with the fields each enabled, in the
order of `eyehil.protocols.opengaze.DATA_FIELDS`. ``CNT`` counts exposures since the start (a client sees gaps when
records were dropped), ``TIME`` is device seconds since the start, ``TIME_TICK`` device microseconds
(``TIME_TICK_FREQUENCY`` 1,000,000). Gaze is mapped by the gazer of the last successful calibration (none
before: POG validity 0). Docs: docs/opengaze.md.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections import Counter
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.camera import Camera, Exposures, Selection
from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.opengaze.calibration import DEFAULT_POINTS, MAX_POINTS, CalibrationRun, Outcome
from eyehil.emulator.device.opengaze.filters import BlinkCounter, FixationFilter
from eyehil.emulator.device.opengaze.samples import (
    CachedGazer,
    EyeGeometry,
    Values,
    exposure_values,
    fraction_to_screen,
)
from eyehil.emulator.device.pupil.calibration import METHODS
from eyehil.emulator.device.pupil.datums import sample_arrays
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.enums import Eye
from eyehil.protocols.native import MAX_RATE_HZ
from eyehil.protocols.opengaze import (
    API_VERSION,
    DATA_FIELDS,
    ENABLE_SEND_DATA,
    OVERLONG,
    OpenGazeError,
    Record,
    ack,
    format_record,
    format_value,
    nack,
    number,
    parse_record,
    state,
)

MAX_BEHIND_S = 0.25
MAX_USER_DATA = 256  # characters of USER_DATA VALUE
MAX_SCREEN_PX = 65536
MAX_CAL_SECONDS = 10.0  # CALIBRATE_DELAY / CALIBRATE_TIMEOUT at most


@dataclass(frozen=True)
class OpenGazeOptions:
    """The device's behaviour (units in the names)."""

    rate_hz: int = 60  # exposures (REC records) per second: 60 as a GP3, 150 as a GP3 HD
    method: str = "auto"  # gazer: auto (by the scene), guestrin, blignaut (`zmq_calibration.fit`)
    screen_px: tuple[int, int] = (1920, 1080)  # SCREEN_SIZE until a client sets it
    delay_s: float = 0.5  # CALIBRATE_DELAY default
    timeout_s: float = 1.0  # CALIBRATE_TIMEOUT default
    fixation_radius_deg: float = 1.0  # the fixation filter's dispersion radius
    serial: str = ""  # SERIAL_ID ("" = derived from the scene and eye)

    def __post_init__(self) -> None:
        if not 1 <= self.rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"rate {self.rate_hz} Hz outside 1..{MAX_RATE_HZ}")
        if self.method not in METHODS:
            raise ValueError(f"gaze method must be one of {METHODS}, got {self.method!r}")


@dataclass(frozen=True)
class Out:
    """A record for client `cid` (None: all), and whether it may be dropped under back-pressure."""

    cid: int | None
    data: bytes
    droppable: bool = False


class OpenGazeDevice:
    """See the module docstring."""

    def __init__(self, subject: Subject, clock: Clock, options: OpenGazeOptions | None = None) -> None:
        self.subject, self.clock = subject, clock
        if hasattr(clock, "paused"):
            subject.pause_clock = clock.paused  # a fast clock's time waits for the subject's exact solves
        self.options = o = options or OpenGazeOptions()
        scene = self.scene = subject.solver.scene
        self.eye_ids = tuple(0 if side == "right" else 1 for side in scene.sides)
        self.camera = Camera(subject, tuple(int(v) for v in scene.camera.resolution_px),
                             tuple(Eye(e) for e in self.eye_ids))
        self.counters: Counter[str] = Counter()
        self.clients: dict[int, set[str]] = {}  # enabled ENABLE_SEND_* switches, ENABLE_SEND_DATA included
        self._next_cid = 1
        self.screen = (0, 0, *o.screen_px)
        self.points: list[tuple[float, float]] = list(DEFAULT_POINTS)
        self.delay_s, self.timeout_s = o.delay_s, o.timeout_s
        self.switches = {"CALIBRATE_SHOW": False, "TRACKER_DISPLAY": False}
        self.user_data, self._user_once, self._user_left = "", "", 0
        self.run: CalibrationRun | None = None
        self.outcome: Outcome | None = None
        self.gazer: CachedGazer | None = None
        solver = subject.solver
        self.geometry = EyeGeometry.of(scene, solver.head.rotation, solver.head.translation,
                                       float(np.asarray(solver.eye.pupil_radius).reshape(-1)[0]))
        distance = float(np.linalg.norm(scene.screen.centre))
        r_mm = distance * np.tan(np.radians(o.fixation_radius_deg))
        self.fixations = FixationFilter((r_mm / scene.screen.size[0], r_mm / scene.screen.size[1]))
        self.blinks = BlinkCounter()
        self.serial = o.serial or "EYEHIL-" + hashlib.sha256(repr((scene.name, scene.sides)).encode()
                                                              ).hexdigest()[:8].upper()
        self.t0_us = clock.now_us()
        self.camera.start(self.t0_us, o.rate_hz, Selection(self.camera.tracked, len(scene.leds)))

    # --- clients -----------------------------------------------------------------------------
    def connect(self) -> int:
        """A new client; nothing is enabled for it."""
        cid, self._next_cid = self._next_cid, self._next_cid + 1
        self.clients[cid] = set()
        return cid

    def disconnect(self, cid: int) -> None:
        self.clients.pop(cid, None)

    def handle(self, cid: int, line: bytes | object) -> list[Out]:
        """Answer one line of client `cid` (see the module docstring)."""
        self.counters["records_received"] += 1
        try:
            if line is OVERLONG:
                raise OpenGazeError("TOO_LONG", "line longer than the limit")
            record = parse_record(line)  # type: ignore[arg-type]
            if record.tag not in ("GET", "SET"):
                raise OpenGazeError("BAD_TAG", record.tag)
            return self._get(cid, record) if record.tag == "GET" else self._set(cid, record)
        except OpenGazeError as exc:
            self.counters["records_refused"] += 1
            rid = ""
            if isinstance(line, bytes):
                with contextlib.suppress(OpenGazeError):
                    rid = parse_record(line).id
            return [Out(cid, nack(rid, exc.code))]

    def show(self, xy: tuple[float, float]) -> None:
        """The subject looks at screen fractions `xy` from now (the emulator's stand-in for the screen)."""
        x, y = fraction_to_screen(self.scene.screen.size, np.array(xy, float))
        t_us = self.clock.now_us()
        self.camera.invalidate(self.subject.look_at((float(x), float(y)), t_us))

    # --- GET / SET -------------------------------------------------------------------------------
    def _value(self, rid: str) -> dict[str, object]:
        """The attributes an ACK of `rid` carries (its current value); OpenGazeError if unknown."""
        w, h = (int(v) for v in self.scene.camera.resolution_px)
        fixed: dict[str, dict[str, object]] = {
            "SCREEN_SIZE": dict(zip(("X", "Y", "WIDTH", "HEIGHT"), self.screen, strict=True)),
            "CAMERA_SIZE": {"WIDTH": w, "HEIGHT": h},
            "PRODUCT_ID": {"VALUE": "GP3"}, "SERIAL_ID": {"VALUE": self.serial},
            "COMPANY_ID": {"VALUE": "eyehil"}, "API_ID": {"MFG_ID": "eyehil", "VER_ID": API_VERSION},
            "TIME_TICK_FREQUENCY": {"FREQ": 1_000_000},
            "CALIBRATE_DELAY": {"VALUE": float(self.delay_s)}, "CALIBRATE_TIMEOUT": {"VALUE": float(self.timeout_s)},
            "CALIBRATE_START": {"STATE": self.run is not None},
            "CALIBRATE_ADDPOINT": self._points_attrs(),
            "CALIBRATE_RESULT_SUMMARY": self._summary(),
            "USER_DATA": {"VALUE": self.user_data},
        }
        if rid in fixed:
            return fixed[rid]
        if rid in self.switches:
            return {"STATE": self.switches[rid]}
        raise OpenGazeError("UNKNOWN_ID", rid[:40])

    def _points_attrs(self) -> dict[str, object]:
        out: dict[str, object] = {"PTS": len(self.points)}
        for k, (x, y) in enumerate(self.points, 1):
            out[f"X{k}"], out[f"Y{k}"] = float(x), float(y)
        return out

    def _summary(self) -> dict[str, object]:
        if self.outcome is None:
            return {"AVE_ERROR": 0.0, "VALID_POINTS": 0}
        err, valid = self.outcome.summary(self.screen[2:])
        return {"AVE_ERROR": err, "VALID_POINTS": valid}

    def _get(self, cid: int, r: Record) -> list[Out]:
        if r.id in DATA_FIELDS or r.id == ENABLE_SEND_DATA:
            return [Out(cid, ack(r.id, STATE=r.id in self.clients[cid]))]
        return [Out(cid, ack(r.id, **self._value(r.id)))]

    def _set(self, cid: int, r: Record) -> list[Out]:
        rid = r.id
        if rid in DATA_FIELDS or rid == ENABLE_SEND_DATA:
            on = state(r)
            (self.clients[cid].add if on else self.clients[cid].discard)(rid)
            return [Out(cid, ack(rid, STATE=on))]
        if rid in self.switches:
            self.switches[rid] = state(r)
            return [Out(cid, ack(rid, STATE=self.switches[rid]))]
        handler = {"CALIBRATE_START": self._calibrate_start, "CALIBRATE_DELAY": self._calibrate_time,
                   "CALIBRATE_TIMEOUT": self._calibrate_time, "CALIBRATE_CLEAR": self._calibrate_points,
                   "CALIBRATE_RESET": self._calibrate_points, "CALIBRATE_ADDPOINT": self._calibrate_points,
                   "SCREEN_SIZE": self._screen_size, "USER_DATA": self._user_data}.get(rid)
        if handler is None:
            self._value(rid)  # a known read-only ID: refused as such; else UNKNOWN_ID
            raise OpenGazeError("READ_ONLY", rid)
        return [Out(cid, handler(r))]

    def _calibrate_start(self, r: Record) -> bytes:
        on = state(r)
        if on:
            if not self.points:
                raise OpenGazeError("NO_POINTS", "CALIBRATE_ADDPOINT first")
            if self.run is not None:
                self.run.close()
            self.run = CalibrationRun(self.scene, self.eye_ids, self.points, self.clock.now_us(), self.delay_s,
                                      self.timeout_s, self.options.method)
            self.counters["calibrations"] += 1
        elif self.run is not None:
            self.run.close()
            self.run = None
            self.counters["calibrations_aborted"] += 1
        return ack("CALIBRATE_START", STATE=on)

    def _calibrate_time(self, r: Record) -> bytes:
        value = number(r, "VALUE", 0.0, MAX_CAL_SECONDS)
        if r.id == "CALIBRATE_DELAY":
            self.delay_s = value
        else:
            self.timeout_s = max(value, 0.1)
        return ack(r.id, VALUE=float(self.delay_s if r.id == "CALIBRATE_DELAY" else self.timeout_s))

    def _calibrate_points(self, r: Record) -> bytes:
        if self.run is not None:
            raise OpenGazeError("BUSY", "a calibration is running")
        if r.id == "CALIBRATE_CLEAR":
            self.points = []
        elif r.id == "CALIBRATE_RESET":
            self.points = list(DEFAULT_POINTS)
        else:
            x, y = number(r, "X", 0.0, 1.0), number(r, "Y", 0.0, 1.0)
            if len(self.points) >= MAX_POINTS:
                raise OpenGazeError("TOO_MANY", f"at most {MAX_POINTS} points")
            self.points.append((x, y))
        return ack(r.id, **self._points_attrs())

    def _screen_size(self, r: Record) -> bytes:
        x, y = (int(number(r, k, -MAX_SCREEN_PX, MAX_SCREEN_PX)) for k in ("X", "Y"))
        w, h = (int(number(r, k, 1, MAX_SCREEN_PX)) for k in ("WIDTH", "HEIGHT"))
        self.screen = (x, y, w, h)
        return ack("SCREEN_SIZE", **self._value("SCREEN_SIZE"))

    def _user_data(self, r: Record) -> bytes:
        value = r.attrs.get("VALUE")
        if value is None:
            raise OpenGazeError("MISSING", "VALUE")
        if len(value) > MAX_USER_DATA:
            raise OpenGazeError("TOO_LONG", f"USER_DATA VALUE longer than {MAX_USER_DATA}")
        dur = int(number(r, "DUR", 0, 1_000_000)) if "DUR" in r.attrs else 0
        if dur:
            self._user_once, self._user_left = value, dur
        else:
            self.user_data, self._user_left = value, 0
        return ack("USER_DATA", VALUE=value, DUR=dur)

    # --- streaming ---------------------------------------------------------------------------------
    def wait_s(self, idle_s: float = 0.05) -> float:
        """Wall seconds until the next exposure is due (at most `idle_s`)."""
        due = self.camera.time_of(self.camera.taken)
        return max(0.0, min(idle_s, self.clock.wall_delay_s(due)))

    def step(self) -> list[Out]:
        """Records due now: calibration events, then the exposures' REC records, then a fit's result."""
        now = self.clock.now_us()
        out = self._calibration_events(now)
        due = self.camera.due(now)
        behind = due - max(1, round(self.options.rate_hz * MAX_BEHIND_S))
        if behind > 0:
            self.camera.skip(behind)
            self.counters["exposures_skipped"] += behind
            due -= behind
        if due > 0:
            first = self.camera.taken
            exp = self.camera.take(due)
            if self.run is not None and self.run.collecting:
                self.run.session.add_samples(exp.time_us / 1e6, *sample_arrays(exp))
            out += self._records(exp, first)
        if self.run is not None:
            outcome = self.run.outcome()
            if outcome is not None:
                out.append(self._finish(outcome))
        return out

    def _calibration_events(self, now_us: int) -> list[Out]:
        if self.run is None:
            return []
        out = []
        for kind, k, t_us in self.run.events(now_us):
            x, y = self.run.points[k]
            if kind == "start":
                self.camera.invalidate(self.subject.look_at(self.run.screen_mm(k), t_us))
            rid = "CALIB_START_PT" if kind == "start" else "CALIB_RESULT_PT"
            out.append(Out(None, format_record("CAL", {"ID": rid, "PT": k + 1, "CALX": float(x), "CALY": float(y)})))
        return out

    def _finish(self, outcome: Outcome) -> Out:
        self.run, self.outcome = None, outcome
        if outcome.gazer is not None:
            self.gazer = CachedGazer(outcome.gazer)
            self.counters["calibrations_successful"] += 1
        else:
            self.counters["calibrations_failed"] += 1
        attrs: dict[str, object] = {"ID": "CALIB_RESULT"}
        for k, p in enumerate(outcome.points, 1):
            attrs |= {f"CALX{k}": p.target[0], f"CALY{k}": p.target[1],
                      f"LX{k}": float(p.gaze[0, 0]), f"LY{k}": float(p.gaze[0, 1]), f"LV{k}": bool(p.valid[0]),
                      f"RX{k}": float(p.gaze[1, 0]), f"RY{k}": float(p.gaze[1, 1]), f"RV{k}": bool(p.valid[1])}
        return Out(None, format_record("CAL", attrs))

    def _records(self, exp: Exposures, first: int) -> list[Out]:
        """One REC per exposure for each client with ENABLE_SEND_DATA on."""
        self.counters["exposures"] += len(exp)
        v = exposure_values(exp, self.scene, self.gazer)
        rows = [self._fields(v, n, first + n) for n in range(len(exp))]
        out = []
        for cid, enabled in self.clients.items():
            if ENABLE_SEND_DATA not in enabled:
                continue
            names = [name for switch, names in DATA_FIELDS.items() if switch in enabled for name in names]
            for row in rows:
                body = "".join(f' {name}="{row[name]}"' for name in names)
                out.append(Out(cid, f"<REC{body} />\r\n".encode(), droppable=True))
        return out

    def _fields(self, v: Values, n: int, count: int) -> dict[str, str]:
        """Every REC field of exposure `n` as text."""
        t_s = (int(v.time_us[n]) - self.t0_us) / 1e6
        fix = self.fixations.update(t_s, v.best[n], bool(v.best_valid[n]))
        bkid, bkdur, bkpmin = self.blinks.update(t_s, bool(v.blink[n]))
        f: dict[str, object] = {"CNT": count, "TIME": t_s, "TIME_TICK": int(v.time_us[n]),
                                "FPOGX": fix.x, "FPOGY": fix.y, "FPOGS": fix.start_s, "FPOGD": fix.duration_s,
                                "FPOGID": fix.fid, "FPOGV": fix.valid,
                                "BPOGX": float(v.best[n, 0]), "BPOGY": float(v.best[n, 1]),
                                "BPOGV": bool(v.best_valid[n]),
                                "CX": 0.0, "CY": 0.0, "CS": 0, "BKID": bkid, "BKDUR": bkdur, "BKPMIN": bkpmin,
                                "DIAL": 0.0, "DIALV": 0, "GSR": 0, "GSRV": 0, "HR": 0, "HRV": 0, "HRP": 0,
                                "USER": self._user()}
        for i, e in enumerate("LR"):
            valid = bool(v.pupil_valid[n, i])
            pos = self.geometry.position_m[i] if valid else np.zeros(3)
            f |= {f"{e}POGX": float(v.pog[n, i, 0]), f"{e}POGY": float(v.pog[n, i, 1]),
                  f"{e}POGV": bool(v.pog_valid[n, i]),
                  f"{e}PCX": float(v.pupil[n, i, 0]), f"{e}PCY": float(v.pupil[n, i, 1]),
                  f"{e}PD": float(v.diameter_px[n, i]), f"{e}PS": 1.0 if valid else 0.0, f"{e}PV": valid,
                  f"{e}EYEX": float(pos[0]), f"{e}EYEY": float(pos[1]), f"{e}EYEZ": float(pos[2]),
                  f"{e}PUPILD": self.geometry.pupil_mm / 1000.0 if valid else 0.0, f"{e}PUPILV": valid,
                  f"{e}PMM": self.geometry.pupil_mm if valid else 0.0, f"{e}PMMV": valid}
        return {k: format_value(val, 6 if k.endswith("PUPILD") else 5) for k, val in f.items()}

    def _user(self) -> str:
        if self._user_left > 0:
            self._user_left -= 1
            return self._user_once
        return self.user_data

    def close(self) -> None:
        """Stop a running calibration's worker."""
        if self.run is not None:
            self.run.close()
            self.run = None
