"""Camera images of the simulated subject, one exposure at a time (the device's FRAMES, and any other facade).

The stable entry point is

    render_exposure(renderer, values, eye_index, rng, *, leds=None, size=(320, 240), centre_px=None) -> Frame

with `renderer = ExposureRenderer.for_subject(subject)` (the subject's solver must be an
`appearance.AppearanceSolver`: `build.build_subject` makes one), `values` one row (E, C) of
`Subject.observe(times).values` (E eyes in the scene's `sides` order), `eye_index` the eye to draw and `rng`
the noise generator. It returns an `eyehil.emulator.render.renderer.Frame`: an 8-bit image of `size` (w, h) px (clipped to
the sensor) whose top-left pixel is sensor pixel `frame.roi_xy`, centred on that eye's pupil (or on
`centre_px`, full-sensor px; the sensor's centre when neither is known) and kept on the sensor, with its
ground truth (`frame.truth`, full-sensor px). `render_region` draws several eyes into one fixed window
(a region of interest, or the full sensor).

A row of NaN (the subject is blinking) draws skin only; `appearance.closed(row, layout)` gives the same
eye with its lids shut, which the device draws during blinks (`frame_stream`). `exposure_rng(seed,
frame_id, eye)` is the generator the device uses for one image: the same seed, frame id and eye give the
same pixels, whatever else was rendered or dropped before.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eyehil.emulator.device.appearance import AppearanceSolver, ChannelLayout, outline_from_rows
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.render.renderer import DEFAULT_ROI, Frame, RenderSettings, render_window, roi_window


@dataclass(frozen=True)
class ExposureRenderer:
    """What `render_exposure` needs besides the observation: the channel layout, the sensor (w, h) px and how
    frames look (`eyehil.emulator.render.renderer.RenderSettings`)."""

    layout: ChannelLayout
    sensor_px: tuple[int, int]
    settings: RenderSettings = field(default_factory=RenderSettings)

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


def render_exposure(renderer: ExposureRenderer, values: np.ndarray, eye_index: int, rng: np.random.Generator, *,
                    leds: int | None = None, size: tuple[int, int] = DEFAULT_ROI,
                    centre_px: np.ndarray | None = None) -> Frame:
    """One eye of one exposure: a window of `size` around its pupil (see the module docstring); `leds`: how
    many LEDs are lit (the first ones; default all)."""
    outline = outline_from_rows(np.asarray(values)[eye_index], renderer.layout, renderer.sensor_px, leds)
    size = renderer.clip(size)
    centre = outline.pupil_centre_px[0] if centre_px is None else np.asarray(centre_px, float)
    origin = roi_window(centre, size, renderer.sensor_px)
    return render_window(outline, rng, origin=origin, size=size, settings=renderer.settings)


def render_region(renderer: ExposureRenderer, values: np.ndarray, eye_indices: tuple[int, ...],
                  region: tuple[int, int, int, int], rng: np.random.Generator, *, leds: int | None = None) -> Frame:
    """The eyes `eye_indices` of one exposure `values` (E, C) drawn into the sensor window `region` (x, y, w, h) px."""
    rows = np.asarray(values)[list(eye_indices)]
    outline = outline_from_rows(rows.reshape(len(eye_indices), -1), renderer.layout, renderer.sensor_px, leds)
    x, y, w, h = region
    return render_window(outline, rng, origin=(x, y), size=(w, h), settings=renderer.settings)


def exposure_rng(seed: int, frame_id: int, eye: int) -> np.random.Generator:
    """The noise generator of the image of `eye` (a protocols Eye value) of exposure `frame_id`, device seed `seed`."""
    return np.random.default_rng([int(seed), int(frame_id), int(eye)])
