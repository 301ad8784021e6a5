"""A Lab Streaming Layer outlet of type ``Gaze`` for the ZeroMQ facade (optional: pylsl, the extra ``lsl``).

One sample per exposure (nominal rate: the exposure rate), ``cf_double64``, NaN where a value is unknown.
Channel metadata follow the XDF gaze meta-data conventions, as Pupil Capture's LSL relay does:
``desc/channels/channel`` with ``label``, ``eye`` (right, left, both), ``type``, ``unit`` and
``coordinate_system``:

| label | eye | type | unit | coordinate system | value |
|---|---|---|---|---|---|
| confidence | both | Confidence | normalized | | gaze confidence (0 without a calibration) |
| norm_pos_x, norm_pos_y | both | ScreenX, ScreenY | normalized | screen | gaze on the screen, origin bottom-left |
| pupil{i}_x, pupil{i}_y | right / left | PupilX, PupilY | pixels | eye{i} | pupil centre in the eye image |
| diameter{i}_2d | right / left | Diameter | pixels | eye{i} | major axis of the pupil ellipse |
| confidence{i} | right / left | Confidence | normalized | eye{i} | pupil confidence |
| glint{i}_{l}_x, glint{i}_{l}_y | right / left | ReflexX, ReflexY | pixels | eye{i} | glint of LED l |

for each tracked eye i (Pupil's ids: 0 right, 1 left) and LED l. Eye-image pixels and the screen's
normalised coordinates are those of the ZeroMQ datums (`zmq_datums`, `zmq_calibration`).

With ``layout="pupil_relay"`` the stream is named and laid out as Pupil Capture's LSL relay (pupil-labs
`pupil_capture_lsl_relay`, outlet v2): name ``pupil_capture``, type ``Gaze``, 22 channels: confidence,
norm_pos_x/y, gaze_point_3d_x/y/z (mm; here the gaze point on the screen in the scene frame), then per eye 0
and 1 eye_center{i}_3d_x/y/z and gaze_normal{i}_x/y/z (NaN: the facade publishes no 3-D eye model), and
diameter{i}_2d (px), diameter{i}_3d (mm; the anatomical pupil, NaN when not detected).

The source id is stable across restarts of the same device (`stable_source_id`: a hash of what defines the
device), so that a recorder (LabRecorder) finds the stream again after a restart.

Network exposure: liblsl reads its configuration once per process from the file named by LSLAPICFG.
Unless the user set LSLAPICFG, `load_pylsl` points it at `LOOPBACK_CONFIG` (written to a temporary file):
stream discovery answers on 127.0.0.1 only (``ListenAddress``), within this machine (``ResolveScope =
machine``, multicast TTL 0), IPv4 only. liblsl 1.18 has no option to bind its per-outlet TCP data port and
UDP time port: they listen on all interfaces (the outlet prints this at start, `exposure`); firewall them,
or run the emulator where that does not matter.

Timestamps are explicit: each sample carries its exposure's mid-exposure time, mapped from the device clock
to LSL's `local_clock` at the push: t_lsl = local_clock() - (device now - t_exposure) / speed.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.pupil.datums import EyeWindow
from eyehil.emulator.device.pupil.gaze import Block

LAYOUTS = ("eyehil", "pupil_relay")


def stable_source_id(*identity: object) -> str:
    """``eyehil-<12 hex digits>`` of `identity` (the scene, eyes, head, address ... of a device): the same
    device gets the same id after a restart."""
    import hashlib

    return "eyehil-" + hashlib.sha256(repr(identity).encode()).hexdigest()[:12]


class LslUnavailableError(ImportError):
    """pylsl or its liblsl is missing (the message says which, and how to install it)."""


LOOPBACK_CONFIG = """[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
ListenAddress = 127.0.0.1
TTLOverride = 0
"""


def use_loopback_config() -> str:
    """Point liblsl at `LOOPBACK_CONFIG` unless LSLAPICFG is set already; return the file liblsl will read."""
    if not os.environ.get("LSLAPICFG"):
        handle, path = tempfile.mkstemp(prefix="eyehil-lsl-", suffix=".cfg")
        with os.fdopen(handle, "w") as f:
            f.write(LOOPBACK_CONFIG)
        os.environ["LSLAPICFG"] = path
    return os.environ["LSLAPICFG"]


def exposure() -> str:
    """What the outlet binds, for the start-up message."""
    cfg = os.environ.get("LSLAPICFG", "")
    loopback = False
    if cfg and os.path.isfile(cfg):
        with open(cfg) as f:
            loopback = f.read() == LOOPBACK_CONFIG
    where = ("discovery on 127.0.0.1 only (this machine)" if loopback
             else f"discovery as configured in {cfg or 'the liblsl defaults'}")
    return f"LSL outlet: {where}; liblsl's data (TCP) and time (UDP) ports listen on all interfaces (no liblsl option)"


def load_pylsl():
    """The pylsl module (liblsl configured for the loopback, `use_loopback_config`), or LslUnavailableError."""
    use_loopback_config()
    try:
        import pylsl
    except ImportError as exc:
        raise LslUnavailableError(f"the LSL outlet needs pylsl: pip install 'eyehil[lsl]' ({exc})") from exc
    except (RuntimeError, OSError) as exc:  # pylsl present, liblsl not found or not loadable
        raise LslUnavailableError(f"pylsl cannot load liblsl: {exc}") from exc
    return pylsl


@dataclass(frozen=True)
class Channel:
    """One channel's metadata."""

    label: str
    eye: str
    type: str
    unit: str
    coordinate_system: str = ""


def gaze_channels(eye_ids: tuple[int, ...], n_leds: int) -> list[Channel]:
    """The channels of the stream, in sample order (see the module docstring)."""
    out = [Channel("confidence", "both", "Confidence", "normalized"),
           Channel("norm_pos_x", "both", "ScreenX", "normalized", "screen"),
           Channel("norm_pos_y", "both", "ScreenY", "normalized", "screen")]
    for i in eye_ids:
        eye, system = ("right", "left")[i], f"eye{i}"
        out += [Channel(f"pupil{i}_x", eye, "PupilX", "pixels", system),
                Channel(f"pupil{i}_y", eye, "PupilY", "pixels", system),
                Channel(f"diameter{i}_2d", eye, "Diameter", "pixels", system),
                Channel(f"confidence{i}", eye, "Confidence", "normalized", system)]
        for led in range(n_leds):
            out += [Channel(f"glint{i}_{led}_x", eye, "ReflexX", "pixels", system),
                    Channel(f"glint{i}_{led}_y", eye, "ReflexY", "pixels", system)]
    return out


def relay_channels() -> list[Channel]:
    """Pupil Capture's LSL relay gaze channels (see the module docstring), in sample order."""
    out = [Channel("confidence", "both", "Confidence", "normalized"),
           *(Channel(f"norm_pos_{a}", "both", f"Screen{a.upper()}", "normalized", "world") for a in "xy"),
           *(Channel(f"gaze_point_3d_{a}", "both", f"Direction{a.upper()}", "mm", "world") for a in "xyz")]
    for kind, label in (("Position", "eye_center{}_3d_{}"), ("Position", "gaze_normal{}_{}")):
        out += [Channel(label.format(i, a), ("right", "left")[i], kind + a.upper(), "mm", "world")
                for i in range(2) for a in "xyz"]
    out += [Channel(f"diameter{i}_2d", ("right", "left")[i], "Diameter", "pixels", f"eye{i}") for i in range(2)]
    out += [Channel(f"diameter{i}_3d", ("right", "left")[i], "Diameter", "mm", f"eye{i}") for i in range(2)]
    return out


def relay_rows(block: Block, eye_ids: tuple[int, ...], screen_centre: np.ndarray, screen_mm: tuple[float, float],
               pupil_mm: float) -> np.ndarray:
    """Samples (N, 22) of a mapped block in `relay_channels` order."""
    n = len(block.time_us)
    out = np.full((n, 22), np.nan)
    out[:, 0], out[:, 1:3] = block.gaze_confidence, block.gaze
    x_mm, y_mm = (0.5 - block.gaze[:, 0]) * screen_mm[0], (block.gaze[:, 1] - 0.5) * screen_mm[1]
    out[:, 3:6] = screen_centre + np.stack([x_mm, y_mm, np.zeros(n)], axis=1)
    for e, eye_id in enumerate(eye_ids):
        out[:, 18 + eye_id] = block.diameter[:, e]
        out[:, 20 + eye_id] = np.where(np.isfinite(block.diameter[:, e]), pupil_mm, np.nan)
    return out


def block_rows(block: Block) -> np.ndarray:
    """Samples (N, channels) of a mapped block, in `gaze_channels` order."""
    n, e = block.confidence.shape
    columns = [block.gaze_confidence[:, None], block.gaze]
    for i in range(e):
        columns += [block.pupil[:, i], block.diameter[:, i, None], block.confidence[:, i, None],
                    block.glints[:, i].reshape(n, -1)]
    return np.concatenate(columns, axis=1).astype(np.float64)


class GazeOutlet:
    """The outlet; `push` one `zmq_gaze.Block` at a time, `close` when done."""

    def __init__(self, windows: list[EyeWindow], n_leds: int, rate_hz: float, clock: Clock, *,
                 name: str = "eyehil", source_id: str | None = None, layout: str = "eyehil",
                 screen: tuple[np.ndarray, tuple[float, float]] | None = None, pupil_mm: float = float("nan")
                 ) -> None:
        """An outlet for the eyes of `windows` with `n_leds` glints each; `clock`: the device clock; `layout`
        "pupil_relay" (name ``pupil_capture``) needs `screen` (centre mm, size mm) and the pupil diameter."""
        if layout not in LAYOUTS:
            raise ValueError(f"LSL layout must be one of {LAYOUTS}, got {layout!r}")
        self._lsl = load_pylsl()
        self.clock, self.layout, self.eye_ids = clock, layout, tuple(w.eye_id for w in windows)
        self.screen, self.pupil_mm = screen, pupil_mm
        if layout == "pupil_relay":
            name, self.channels = "pupil_capture", relay_channels()
        else:
            self.channels = gaze_channels(self.eye_ids, n_leds)
        info = self._lsl.StreamInfo(name=name, type="Gaze", channel_count=len(self.channels),
                                    nominal_srate=float(rate_hz), channel_format=self._lsl.cf_double64,
                                    source_id=source_id or name)
        desc = info.desc()
        desc.append_child_value("manufacturer", "eyehil")
        desc.append_child_value("model", "eyehil virtual tracker, ZeroMQ facade")
        xml = desc.append_child("channels")
        for ch in self.channels:
            node = xml.append_child("channel")
            for key in ("label", "eye", "type", "unit", "coordinate_system"):
                if getattr(ch, key):
                    node.append_child_value(key, getattr(ch, key))
        self.pushed = 0
        self._outlet = self._lsl.StreamOutlet(info)
        print(exposure(), flush=True)

    def lsl_times(self, time_us: np.ndarray) -> np.ndarray:
        """LSL `local_clock` times (s) of device times (us), mapped now."""
        now_local, now_us = self._lsl.local_clock(), self.clock.now_us()
        speed = float(getattr(self.clock, "speed", 1.0))
        return now_local - (now_us - np.asarray(time_us, dtype=np.float64)) / 1e6 / speed

    def push(self, block: Block) -> None:
        """Push the block's samples with their explicit timestamps."""
        if self._outlet is None or len(block.time_us) == 0:
            return
        rows = (relay_rows(block, self.eye_ids, self.screen[0], self.screen[1], self.pupil_mm)
                if self.layout == "pupil_relay" else block_rows(block))
        self._outlet.push_chunk(rows, self.lsl_times(block.time_us).tolist())
        self.pushed += len(block.time_us)

    def close(self) -> None:
        """Destroy the outlet (its sockets and threads in liblsl); idempotent."""
        self._outlet = None
