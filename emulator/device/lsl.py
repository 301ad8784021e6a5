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

Timestamps are explicit: each sample carries its exposure's mid-exposure time, mapped from the device clock
to LSL's `local_clock` at the push: t_lsl = local_clock() - (device now - t_exposure) / speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.pupil.datums import EyeWindow
from eyehil.emulator.device.pupil.gaze import Block


class LslUnavailableError(ImportError):
    """pylsl or its liblsl is missing (the message says which, and how to install it)."""


def load_pylsl():
    """The pylsl module, or LslUnavailableError with the reason."""
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
                 name: str = "eyehil", source_id: str | None = None) -> None:
        """An outlet for the eyes of `windows` with `n_leds` glints each; `clock`: the device clock."""
        self._lsl = load_pylsl()
        self.clock = clock
        self.channels = gaze_channels(tuple(w.eye_id for w in windows), n_leds)
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

    def lsl_times(self, time_us: np.ndarray) -> np.ndarray:
        """LSL `local_clock` times (s) of device times (us), mapped now."""
        now_local, now_us = self._lsl.local_clock(), self.clock.now_us()
        speed = float(getattr(self.clock, "speed", 1.0))
        return now_local - (now_us - np.asarray(time_us, dtype=np.float64)) / 1e6 / speed

    def push(self, block: Block) -> None:
        """Push the block's samples with their explicit timestamps."""
        if self._outlet is None or len(block.time_us) == 0:
            return
        self._outlet.push_chunk(block_rows(block), self.lsl_times(block.time_us).tolist())
        self.pushed += len(block.time_us)

    def close(self) -> None:
        """Destroy the outlet (its sockets and threads in liblsl); idempotent."""
        self._outlet = None
