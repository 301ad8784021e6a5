"""`frame.world` for the ZeroMQ facade: the scene camera's view, the screen with the current target.

The world camera. Pupil Capture's world camera is worn on the head and sees the screen among other things;
its gaze `norm_pos` is in that camera's image. This facade's "world" is the scene's screen itself (gaze
`norm_pos` is normalised screen coordinates, docs/zmq.md "Screen coordinates"), so the world camera here is
an ideal camera that sees exactly the screen, edge to edge, fronto-parallel: a gaze datum's `norm_pos`
indexes its image as Pupil's does the world image, pixel (x, y) = (nx w - 0.5, (1 - ny) h - 0.5) (OpenCV
pixel centres, origin top-left). Size: `width` px wide (default 640) and the screen's aspect ratio (height
rounded to an even number of px). Known answer (guestrin2006, 377 x 301 mm, 640 px): 640 x 510.98 -> 640 x 510
(even), the screen centre at pixel (319.5, 254.5).

What it shows (`render_world`): the screen, uniform gray (`SCREEN_GRAY`), and the current target as
Pupil's screen marker looks (concentric: a black disc of `MARKER_MM` radius, a white ring from 0.6 of it, a
black centre dot within 0.3 of it), no noise, no lens. The current target at time t (`TargetTrack`): the
latest target shown to the subject at or before t (a calibration marker, reference data, an
`eyehil.stimulus`: `DeviceThread.show`), from its onset, not from the subject's saccade; before any, the
gaze script's target (the end point of a saccade under way, the moving point of a pursuit, the point held).

Publishing (`WorldPublisher`, thread "eyehil-zmq-world", `frames.ImageThread`): the device thread offers
every k-th exposure, k = max(1, round(rate / world_rate)), while frame publishing is on, in the frame
publisher's format; at most `frames.IMAGE_QUEUE` wait, more are dropped and counted (`world_dropped`); `index`
counts the frames offered, dropped ones included. Payload as `frame.eye.<id>` (`protocols.pupil.frame_datum`).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import zmq

from eyehil.emulator.device.gaze import Kind, Timeline
from eyehil.emulator.device.pupil.frames import ImageThread, encode_image
from eyehil.protocols.pupil import frame_datum

WORLD_WIDTH_PX = 640
MIN_WIDTH_PX, MAX_WIDTH_PX = 16, 4096
SCREEN_GRAY = 128
MARKER_MM = 8.0  # radius of the target marker on the screen
MAX_SHOWN = 64  # targets remembered for `TargetTrack.at` (the oldest go first)


@dataclass(frozen=True)
class WorldView:
    """The world camera: a screen of `screen_mm` (w, h) mm seen edge to edge in `size` (w, h) px."""

    screen_mm: tuple[float, float]
    size: tuple[int, int]

    @classmethod
    def of_screen(cls, screen_mm: tuple[float, float], width_px: int = WORLD_WIDTH_PX) -> WorldView:
        """`width_px` wide (`MIN_WIDTH_PX`..`MAX_WIDTH_PX`), the screen's aspect ratio, an even height."""
        if not MIN_WIDTH_PX <= width_px <= MAX_WIDTH_PX:
            raise ValueError(f"world width {width_px} px outside {MIN_WIDTH_PX}..{MAX_WIDTH_PX}")
        w_mm, h_mm = float(screen_mm[0]), float(screen_mm[1])
        height = max(2, 2 * round(width_px * h_mm / w_mm / 2))
        return cls((w_mm, h_mm), (int(width_px), int(height)))

    def pixel_of(self, screen_xy_mm: np.ndarray) -> np.ndarray:
        """Image px (x right, y down; OpenCV centres) of screen points (..., 2) mm (scene screen frame: from
        the centre, x toward the subject's left, y up)."""
        xy = np.asarray(screen_xy_mm, float)
        nx = 0.5 - xy[..., 0] / self.screen_mm[0]
        ny = 0.5 + xy[..., 1] / self.screen_mm[1]
        return np.stack([nx * self.size[0] - 0.5, (1.0 - ny) * self.size[1] - 0.5], axis=-1)


def render_world(view: WorldView, target_mm: tuple[float, float] | None) -> np.ndarray:
    """The world image (h, w) uint8: the gray screen and, unless None, the target marker at `target_mm`."""
    w, h = view.size
    image = np.full((h, w), SCREEN_GRAY, np.uint8)
    if target_mm is None:
        return image
    cx, cy = view.pixel_of(np.asarray(target_mm, float))
    sx, sy = w / view.screen_mm[0], h / view.screen_mm[1]  # px per mm
    x0, x1 = int(np.floor(cx - MARKER_MM * sx)), int(np.ceil(cx + MARKER_MM * sx)) + 1
    y0, y1 = int(np.floor(cy - MARKER_MM * sy)), int(np.ceil(cy + MARKER_MM * sy)) + 1
    x0, x1, y0, y1 = max(x0, 0), min(x1, w), max(y0, 0), min(y1, h)
    if x0 >= x1 or y0 >= y1:  # off the screen
        return image
    ys, xs = np.mgrid[y0:y1, x0:x1]
    r_mm = np.hypot((xs - cx) / sx, (ys - cy) / sy)
    patch = image[y0:y1, x0:x1]
    patch[r_mm <= MARKER_MM] = 0
    patch[r_mm <= 0.6 * MARKER_MM] = 255
    patch[r_mm <= 0.3 * MARKER_MM] = 0
    return image


class TargetTrack:
    """The current target on the screen (see the module docstring); used by the device thread only."""

    def __init__(self) -> None:
        self._shown: deque[tuple[int, tuple[float, float]]] = deque(maxlen=MAX_SHOWN)  # (onset us, screen mm)

    def shown(self, screen_mm: tuple[float, float], onset_us: int) -> None:
        """A target appears at `onset_us` (targets are kept in onset order; an earlier onset replaces the
        later ones, as the subject's plan does)."""
        while self._shown and self._shown[-1][0] >= onset_us:
            self._shown.pop()
        self._shown.append((int(onset_us), (float(screen_mm[0]), float(screen_mm[1]))))

    def at(self, t_us: int, timeline: Timeline) -> tuple[float, float]:
        """The target at device time `t_us`: the latest shown by then, else the gaze script's."""
        for onset, xy in reversed(self._shown):
            if onset <= t_us:
                return xy
        return script_target(timeline, t_us)


def script_target(timeline: Timeline, t_us: int) -> tuple[float, float]:
    """Where a gaze script's stimulus is at `t_us`: a saccade's end point, a pursuit's moving point, the point
    held."""
    starts = [p.start_us for p in timeline.pieces]
    piece = timeline.pieces[max(0, int(np.searchsorted(starts, t_us, side="right")) - 1)]
    if piece.kind == Kind.MOVE and not piece.smooth:
        return timeline.position(t_us)
    return piece.b


@dataclass(frozen=True)
class WorldJob:
    index: int
    timestamp: float  # Pupil time (s)
    target_mm: tuple[float, float] | None
    fmt: str


class WorldPublisher(ImageThread):
    """Renders and publishes `frame.world`; see the module docstring."""

    THREAD_NAME = "eyehil-zmq-world"

    def __init__(self, context: zmq.Context, endpoint: str, view: WorldView, *, hwm: int = 1000) -> None:
        """Publish to the backbone's XSUB at `endpoint`; call `start`, then `close`."""
        super().__init__(context, endpoint, hwm)
        self.view = view
        self._index = 0

    def offer(self, timestamp: float, target_mm: tuple[float, float] | None, fmt: str) -> None:
        """A world frame is due at Pupil time `timestamp` (s) with the target at `target_mm`; device thread."""
        self._submit(WorldJob(self._index, timestamp, target_mm, fmt), 1)
        self._index += 1

    def _publish(self, job: WorldJob) -> None:
        data = encode_image(render_world(self.view, job.target_mm), job.fmt)
        w, h = self.view.size
        self._send(frame_datum("world", job.index, job.timestamp, w, h, job.fmt, data))
