"""`--record-video FILE`: what the page shows of the eyes (images with overlays, side by side) as MP4 or animated PNG.

The session hands each image it shows (`image(image, record)`) and each tick (`tick(message)`); every tick
writes one frame: per eye of the device (right, then left) the last camera image if one came within
`STALE_S`, else the rendering of the last features, with the overlay (`eyehil.drivers.view.overlay`). ``.mp4``
streams to disk (OpenCV's mp4v codec) at `fps`; ``.png`` / ``.apng`` keeps at most `MAX_PNG_FRAMES` frames in
memory (the rest are counted in `skipped`) and writes them with `cv2.imwriteanimation` on `close`.
Frames are written at most `fps` times a second of wall time.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import cv2
import numpy as np

from eyehil.drivers.view.overlay import PANEL, draw_overlay, features_panel, fit, image_panel
from eyehil.protocols.enums import Eye
from eyehil.protocols.images import Image

STALE_S = 1.0
MAX_PNG_FRAMES = 600
EYES = ("right", "left")


class VideoRecorder:
    """See the module docstring."""

    def __init__(self, path: str | Path, fps: float = 30.0) -> None:
        self.path, self.fps = Path(path), fps
        suffix = self.path.suffix.lower()
        if suffix not in (".mp4", ".png", ".apng"):
            raise ValueError(f"--record-video: {self.path} must end in .mp4, .png or .apng")
        self.animated_png = suffix != ".mp4"
        self.frames = self.skipped = 0
        self._writer: cv2.VideoWriter | None = None
        self._frame_size = PANEL
        self._png: list[np.ndarray] = []
        self._images: dict[str, tuple[float, np.ndarray, tuple[int, int], dict | None]] = {}
        self._last_write = 0.0
        self._lock = threading.Lock()

    def image(self, image: Image, record: dict | None = None) -> None:
        """A camera image the page shows, with the features drawn over it."""
        if image.eye is Eye.BOTH:
            return
        with self._lock:
            self._images[Eye(image.eye).name.lower()] = (time.monotonic(), image.pixels, (image.roi_x, image.roi_y),
                                                          record)

    def tick(self, message: dict) -> None:
        """A page update (`eyehil.drivers.view.session` "tick"): write one frame (at most `fps` per second)."""
        now = time.monotonic()
        if now - self._last_write < 1 / self.fps:
            return
        eyes = [e for e in EYES if e in message["eyes"] or e in self._images]
        if not eyes:
            return
        self._last_write = now
        self._write(np.hstack([self._panel(e, message["eyes"].get(e), now) for e in eyes]))

    def _panel(self, eye: str, record: dict | None, now: float) -> np.ndarray:
        with self._lock:
            got = self._images.get(eye)
        if got is not None and now - got[0] < STALE_S:
            _, pixels, origin, own = got
            return fit(draw_overlay(image_panel(pixels), own or record, origin))
        panel, origin = features_panel(record, PANEL)
        return draw_overlay(panel, record, origin)

    def _write(self, frame: np.ndarray) -> None:
        if self.animated_png:
            if len(self._png) >= MAX_PNG_FRAMES:
                self.skipped += 1
                return
            self._png.append(frame)
        else:
            if self._writer is None:
                size = self._frame_size = (frame.shape[1], frame.shape[0])
                self._writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, size)
                if not self._writer.isOpened():
                    raise OSError(f"cannot write {self.path} with OpenCV's mp4v codec")
            if (frame.shape[1], frame.shape[0]) != self._frame_size:
                frame = fit(frame, self._frame_size)
            self._writer.write(frame)
        self.frames += 1

    def close(self) -> Path:
        """Finish the file; return its path."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self.animated_png and self._png:
            animation = cv2.Animation()
            width = max(f.shape[1] for f in self._png)
            animation.frames = [fit(f, (width, PANEL[1])) for f in self._png]
            animation.durations = [round(1000 / self.fps)] * len(self._png)
            if not cv2.imwriteanimation(str(self.path), animation):
                raise OSError(f"cannot write the animated PNG {self.path}")
            self._png.clear()
        return self.path
