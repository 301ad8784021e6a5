"""Pupil time, the eye images' windows, and the `pupil.<id>.2d` / `glint.<id>` datums of the device's exposures.

Pupil time (s) is the device clock (`eyehil.emulator.device.clock`) in seconds plus an offset that Pupil Remote's
``T <float>`` sets so that Pupil time equals the float at that moment; ``t`` reads it.

Eye images. Pupil Capture has one camera per eye; this device is a remote tracker with one camera that sees
both eyes. Each tracked eye (Pupil's ids: 0 = the subject's right eye, 1 = the left eye, as `Eye.RIGHT`,
`Eye.LEFT`) is presented as its own eye camera whose image is a fixed window of the sensor: `size` (w, h) px
centred on that eye's pupil while the subject fixates the screen centre (kept on the sensor), or the whole
sensor (`size=None`). Pupil datums are in that window's pixels (OpenCV convention: origin at the centre of
the top-left pixel, x right, y down): full-sensor px minus the window origin, and
``norm_pos = (x / w, 1 - y / h)`` (origin bottom-left). Known answer: a pupil at sensor (330, 250) in the
window at (160, 130) of 320 x 240 px is at (170, 120) in the eye image, norm_pos (0.53125, 0.5).

A pupil that is not detected (blink, off the window or the sensor) is published with confidence 0, centre,
axes and diameter 0. Glints (one per LED, our extra key) carry `valid`; invalid glints have center (0, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from eyehil.emulator.device.camera import Exposures
from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.solver import FeatureSolver
from eyehil.emulator.render.renderer import roi_window
from eyehil.protocols.enums import GlintFlags, PupilFlags
from eyehil.protocols.pupil import glint_datum, glint_entry, pupil_datum


class PupilTime:
    """Pupil time (s): the device clock's seconds plus `offset_s` (set by Pupil Remote's ``T``); thread-safe."""

    def __init__(self, clock: Clock) -> None:
        """Pupil time starts equal to device time."""
        self.clock = clock
        self.offset_s = 0.0  # one float, replaced atomically

    def now(self) -> float:
        """Pupil time now (s)."""
        return self.clock.now_us() / 1e6 + self.offset_s

    def of_us(self, t_us: np.ndarray | int) -> np.ndarray | float:
        """Pupil time (s) of device times (us)."""
        return np.asarray(t_us, dtype=np.float64) / 1e6 + self.offset_s

    def to_us(self, t_s: float) -> int:
        """Device time (us) of a Pupil time (s); a time that is not finite or beyond +-2**62 us is clipped there
        (a peer's timestamp must never raise on the device thread)."""
        us = (float(t_s) - self.offset_s) * 1e6
        if not math.isfinite(us):
            us = 0.0 if math.isnan(us) else math.copysign(2.0**62, us)
        return round(min(max(us, -(2.0**62)), 2.0**62))

    def set_now(self, value_s: float) -> None:
        """Make Pupil time equal `value_s` now (``T <float>``)."""
        self.offset_s = float(value_s) - self.clock.now_us() / 1e6


@dataclass(frozen=True)
class EyeWindow:
    """The eye camera image of eye `eye_id`: the sensor window at (x0, y0) px of `size` (w, h) px."""

    eye_id: int
    x0: int
    y0: int
    width: int
    height: int

    @property
    def region(self) -> tuple[int, int, int, int]:
        """(x0, y0, w, h) px, full sensor: what the renderer draws (`render_pool.RenderJob.region`)."""
        return self.x0, self.y0, self.width, self.height

    @property
    def origin(self) -> np.ndarray:
        """(x0, y0) px, full sensor."""
        return np.array([self.x0, self.y0], dtype=float)

    @property
    def size(self) -> tuple[int, int]:
        """(w, h) px."""
        return self.width, self.height

    def contains(self, xy: np.ndarray) -> bool:
        """True if full-sensor point `xy` lies on the window's pixels."""
        x, y = float(xy[0]) - self.x0, float(xy[1]) - self.y0
        return -0.5 <= x < self.width - 0.5 and -0.5 <= y < self.height - 0.5


def eye_windows(solver: FeatureSolver, eye_ids: tuple[int, ...], size: tuple[int, int] | None) -> list[EyeWindow]:
    """The window of each tracked eye (`eye_ids` in the solver's order), see the module docstring."""
    sensor = tuple(int(v) for v in solver.scene.camera.resolution_px)
    if size is None:
        return [EyeWindow(i, 0, 0, *sensor) for i in eye_ids]
    size = (min(int(size[0]), sensor[0]), min(int(size[1]), sensor[1]))  # at most the sensor
    primary = solver.exact(np.zeros((1, 2)))[0]  # (E, C): features while fixating the screen centre
    windows = []
    for e, eye_id in enumerate(eye_ids):
        x0, y0 = roi_window(primary[e, 0:2], size, sensor)
        windows.append(EyeWindow(eye_id, x0, y0, *size))
    return windows


def exposure_datums(exp: Exposures, windows: list[EyeWindow], time: PupilTime) -> list[list[dict[str, Any]]]:
    """Per exposure of `exp`, the `pupil.<id>.2d` and `glint.<id>` datums of each eye (in window order: pupil,
    glint, pupil, glint ...). The arrays of the whole batch are converted to Python numbers once: the facade
    builds 2,000 such datums a second."""
    b = exp.batch
    ts = np.asarray(time.of_us(exp.time_us), float).tolist()
    per_eye = []
    for e, win in enumerate(windows):
        origin = win.origin
        xy = b.centre[:, e] - origin  # (N, 2) window px
        found = (((b.flags[:, e] & PupilFlags.DETECTED) != 0) & (xy[:, 0] >= -0.5) & (xy[:, 0] < win.width - 0.5)
                 & (xy[:, 1] >= -0.5) & (xy[:, 1] < win.height - 0.5))
        valid = (b.glint_flags[:, e] & GlintFlags.VALID) != 0  # (N, G)
        glint_xy = np.where(valid[..., None], b.glint_xy[:, e] - origin, 0.0)
        per_eye.append((win, np.where(found[:, None], xy, 0.0).tolist(),
                        np.where(found[:, None], b.axes[:, e], 0.0).tolist(),
                        np.where(found, b.angle_deg[:, e], 0.0).tolist(),
                        np.where(found, b.confidence[:, e], 0.0).tolist(),
                        glint_xy.tolist(), valid.tolist(), b.glint_led[:, e].tolist()))
    out = []
    for n, t in enumerate(ts):
        datums = []
        for win, xy, axes, angle, confidence, glint_xy, valid, leds in per_eye:
            glints = [glint_entry(led, g, ok) for led, g, ok in zip(leds[n], glint_xy[n], valid[n], strict=True)]
            datums.append(pupil_datum(win.eye_id, t, xy[n], axes[n], angle[n], confidence[n], win.size, glints))
            datums.append(glint_datum(win.eye_id, t, glints))
        out.append(datums)
    return out


def sample_arrays(exp: Exposures, leds: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Full-sensor pupil centres (N, E, 2), glints (N, E, G, 2) of the first `leds` LEDs (default all), and
    validity (N, E): pupil detected and every glint used valid (NaN where invalid), for the estimators."""
    b = exp.batch
    g = b.glint_xy.shape[2] if leds is None else leds
    glint_ok = ((b.glint_flags[:, :, :g] & GlintFlags.VALID) != 0).all(-1)
    valid = ((b.flags & PupilFlags.DETECTED) != 0) & glint_ok
    pupil = np.where(valid[..., None], b.centre, np.nan)
    glints = np.where(valid[..., None, None], b.glint_xy[:, :, :g], np.nan)
    return pupil, glints, valid
