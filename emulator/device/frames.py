"""Camera images of the simulated subject, one exposure at a time (the device's FRAMES, and any other facade).

The stable entry point is

    render_exposure(renderer, values, eye_index, rng, *, leds=None, size=(320, 240), centre_px=None) -> Frame

with `renderer = ExposureRenderer.for_subject(subject)` (the subject's solver must be an
`appearance.AppearanceSolver`: `build.build_subject` makes one), `values` one row (E, C) of
`Subject.observe(times).values` (E eyes in the scene's `sides` order), `eye_index` the eye to draw and `rng`
the noise (`exposure_noise`, or any numpy generator). It returns a `render.renderer.Frame`: an 8-bit image of
`size` (w, h) px (clipped to the sensor) whose top-left pixel is sensor pixel `frame.roi_xy`, centred on that
eye's pupil (or on `centre_px`, full-sensor px; the sensor's centre when neither is known) and kept on the
sensor, with its ground truth (`frame.truth`, full-sensor px). `render_region` draws several eyes into one fixed window
(a region of interest, or the full sensor).

A row of NaN (the subject is blinking) draws skin only; `appearance.closed(row, layout)` gives the same
eye with its lids shut, which the device draws during blinks (`frame_stream`). `exposure_noise(seed,
frame_id, eye)` is the noise the device uses for one image (`eyehil.emulator.render.noise.CounterNoise`): the same
seed, frame id and eye give the same pixels, whatever else was rendered or dropped before.

Drawn canvases are remembered (`CanvasCache`, a few per renderer): an exposure whose channels, window and lit
LEDs equal those of a recent one (a fixation without jitter, a blink) is not drawn again; only the sensor's
noise is new. The noiseless canvas is a function of those inputs alone, and drawing takes no random numbers
unless eyelashes are drawn (then nothing is remembered), so the image is bit for bit the one drawn afresh.
A 320 x 240 window costs about a fifth of its full rendering when remembered.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver, ChannelLayout, outline_from_rows
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.geometry import EyeOutline
from eyehil.emulator.render.noise import CounterNoise, Noise, exposure_key
from eyehil.emulator.render.renderer import (
    DEFAULT_ROI,
    Canvas,
    Frame,
    RenderSettings,
    draw_window,
    expose_canvas,
    roi_window,
)

CANVASES = 4  # canvases a renderer remembers (a 640 x 480 one holds 1.2 MB)


class CanvasCache:
    """The last `entries` canvases drawn, by what they were drawn from (module docstring); thread-safe. A pickled
    cache (a render worker's copy of its renderer) arrives empty. `hits` and `misses` count the look-ups."""

    def __init__(self, entries: int = CANVASES) -> None:
        self.entries = entries
        self.hits = self.misses = 0
        self._canvases: OrderedDict[tuple, tuple[EyeOutline, tuple[int, int], Canvas]] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple) -> tuple[EyeOutline, tuple[int, int], Canvas] | None:
        """The outline, window origin and canvas drawn for `key`, or None."""
        with self._lock:
            found = self._canvases.get(key)
            if found is None:
                self.misses += 1
            else:
                self.hits += 1
                self._canvases.move_to_end(key)
            return found

    def put(self, key: tuple, outline: EyeOutline, origin: tuple[int, int], canvas: Canvas) -> None:
        """Remember a copy of `canvas` (drawn for `key`), forgetting the least recently used beyond `entries`."""
        kept = Canvas(canvas.signal.copy(), canvas.boxes)
        with self._lock:
            self._canvases[key] = (outline, origin, kept)
            while len(self._canvases) > self.entries:
                self._canvases.popitem(last=False)

    def __len__(self) -> int:
        return len(self._canvases)

    def __getstate__(self) -> dict:
        return {"entries": self.entries}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["entries"])


@dataclass(frozen=True)
class ExposureRenderer:
    """What `render_exposure` needs besides the observation: the channel layout, the sensor (w, h) px and how
    frames look (`eyehil.emulator.render.renderer.RenderSettings`); the canvases it drew last (`canvases`)."""

    layout: ChannelLayout
    sensor_px: tuple[int, int]
    settings: RenderSettings = field(default_factory=RenderSettings)
    canvases: CanvasCache = field(default_factory=CanvasCache, compare=False, repr=False)

    @classmethod
    def for_subject(cls, subject: Subject, settings: RenderSettings | None = None) -> ExposureRenderer:
        """The renderer of `subject`'s observations; its solver must carry appearance channels."""
        solver = subject.solver
        if not isinstance(solver, AppearanceSolver):
            raise TypeError("frames need a subject whose solver is an AppearanceSolver (see build.build_subject)")
        sensor = tuple(int(v) for v in solver.scene.camera.resolution_px)
        return cls(solver.layout, sensor, settings or RenderSettings())

    def clip(self, size: tuple[int, int]) -> tuple[int, int]:
        """`size` (w, h) px limited to the sensor."""
        return min(int(size[0]), self.sensor_px[0]), min(int(size[1]), self.sensor_px[1])


def render_exposure(renderer: ExposureRenderer, values: np.ndarray, eye_index: int, rng: Noise, *,
                    leds: int | None = None, size: tuple[int, int] = DEFAULT_ROI,
                    centre_px: np.ndarray | None = None) -> Frame:
    """One eye of one exposure: a window of `size` around its pupil (see the module docstring); `leds`: how
    many LEDs are lit (the first ones; default all)."""
    row = np.asarray(values, dtype=float)[eye_index]
    size = renderer.clip(size)
    centre = None if centre_px is None else np.asarray(centre_px, float)
    key = ("eye", row.tobytes(), leds, size, None if centre is None else centre.tobytes())

    def window() -> tuple[EyeOutline, tuple[int, int]]:
        outline = outline_from_rows(row, renderer.layout, renderer.sensor_px, leds)
        return outline, roi_window(outline.pupil_centre_px[0] if centre is None else centre, size, renderer.sensor_px)

    return _render(renderer, key, window, size, rng)


def render_region(renderer: ExposureRenderer, values: np.ndarray, eye_indices: tuple[int, ...],
                  region: tuple[int, int, int, int], rng: Noise, *, leds: int | None = None) -> Frame:
    """The eyes `eye_indices` of one exposure `values` (E, C) drawn into the sensor window `region` (x, y, w, h) px."""
    rows = np.asarray(values, dtype=float)[list(eye_indices)].reshape(len(eye_indices), -1)
    x, y, w, h = (int(v) for v in region)
    key = ("region", rows.tobytes(), rows.shape, leds, (x, y, w, h))

    def window() -> tuple[EyeOutline, tuple[int, int]]:
        return outline_from_rows(rows, renderer.layout, renderer.sensor_px, leds), (x, y)

    return _render(renderer, key, window, (w, h), rng)


def _render(renderer: ExposureRenderer, key: tuple, window: Callable[[], tuple[EyeOutline, tuple[int, int]]],
            size: tuple[int, int], rng: Noise) -> Frame:
    """The frame of the window `window()` gives (outline, origin), its canvas remembered under `key` where drawing
    draws no random numbers."""
    settings = renderer.settings
    cacheable = settings.appearance.lashes == 0
    found = renderer.canvases.get(key) if cacheable else None
    if found is None:
        outline, origin = window()
        canvas = draw_window(outline, rng, origin=origin, size=size, settings=settings)
        if cacheable:
            renderer.canvases.put(key, outline, origin, canvas)
    else:
        outline, origin, canvas = found
    image = expose_canvas(canvas, rng, settings)
    return Frame(image=image, roi_xy=origin, outline=outline, sensor_px=outline.sensor_px)


def exposure_noise(seed: int, frame_id: int, eye: int) -> CounterNoise:
    """The noise of the image of `eye` (a protocols Eye value) of exposure `frame_id`, device seed `seed`."""
    return CounterNoise(exposure_key(seed, frame_id, eye))
