"""Remembered canvases (`frames.CanvasCache`): an exposure drawn from the same channels, window and LEDs as a
recent one reuses its noiseless canvas, and its image is bit for bit the one drawn afresh (issue 16: frames at the
device's rate)."""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.frames import CANVASES, ExposureRenderer, exposure_noise, render_exposure, render_region
from eyehil.emulator.render.renderer import Appearance, RenderSettings, Sensor

PERIOD_US = 10_000


@pytest.fixture(scope="module")
def subject():
    return build_subject(DeviceOptions(script="demo", sides="both", clock="fast"))


@pytest.fixture(scope="module")
def values(subject) -> np.ndarray:
    """Channels (N, E, C) of 1.2 s of the demo script: the first fixation (0.8 s), then the move to the second."""
    return subject.observe(np.arange(0, 1_200_000, PERIOD_US)).values


def _fresh(renderer: ExposureRenderer) -> ExposureRenderer:
    """The same renderer with an empty cache."""
    return replace(renderer, canvases=type(renderer.canvases)())


def test_a_fixation_is_drawn_once_and_every_image_equals_a_fresh_render(subject, values) -> None:
    renderer = ExposureRenderer.for_subject(subject)
    repeats = sum(np.array_equal(a, b, equal_nan=True) for a, b in zip(values[:-1, 0], values[1:, 0], strict=True))
    assert 40 <= repeats < len(values) - 1  # the demo's fixation holds the geometry; the move changes it
    for k, row in enumerate(values):
        frame = render_exposure(renderer, row, 0, exposure_noise(7, k, 1))
        alone = render_exposure(_fresh(renderer), row, 0, exposure_noise(7, k, 1))
        assert frame.roi_xy == alone.roi_xy and np.array_equal(frame.image, alone.image), k
        assert len(renderer.canvases) <= CANVASES
    assert renderer.canvases.hits == repeats and renderer.canvases.misses == len(values) - repeats
    # a remembered canvas gives a new noise realisation per exposure, not the same image
    a = render_exposure(renderer, values[10], 0, exposure_noise(7, 1000, 1))
    b = render_exposure(renderer, values[10], 0, exposure_noise(7, 1001, 1))
    assert not np.array_equal(a.image, b.image)


def test_regions_and_windows_are_remembered_apart(subject, values) -> None:
    renderer = ExposureRenderer.for_subject(subject)
    row = values[5]
    region = render_region(renderer, row, (0, 1), (0, 0, 640, 480), exposure_noise(1, 0, 3))
    window = render_exposure(renderer, row, 0, exposure_noise(1, 0, 1), size=(200, 160))
    other_eye = render_exposure(renderer, row, 1, exposure_noise(1, 0, 2), size=(200, 160))
    one_led = render_exposure(renderer, row, 0, exposure_noise(1, 0, 1), size=(200, 160), leds=1)
    assert renderer.canvases.misses == 4 and renderer.canvases.hits == 0
    again = render_region(renderer, row, (0, 1), (0, 0, 640, 480), exposure_noise(1, 0, 3))
    assert renderer.canvases.hits == 1 and np.array_equal(again.image, region.image)
    def fresh_render(eye_index: int, eye: int, **kw):
        return render_exposure(_fresh(renderer), row, eye_index, exposure_noise(1, 0, eye), size=(200, 160), **kw)

    pairs = ((window, fresh_render(0, 1)), (other_eye, fresh_render(1, 2)), (one_led, fresh_render(0, 1, leds=1)))
    for frame, fresh in pairs:
        assert np.array_equal(frame.image, fresh.image) and frame.roi_xy == fresh.roi_xy
    assert not np.array_equal(window.image, one_led.image)  # one glint fewer


def test_eyelashes_draw_random_numbers_so_nothing_is_remembered(subject, values) -> None:
    lashes = RenderSettings(appearance=Appearance(lashes=12))
    renderer = ExposureRenderer.for_subject(subject, lashes)
    first = render_exposure(renderer, values[3], 0, exposure_noise(2, 3, 1))
    second = render_exposure(renderer, values[3], 0, exposure_noise(2, 3, 1))
    assert len(renderer.canvases) == 0 and renderer.canvases.hits == 0
    assert np.array_equal(first.image, second.image)


def test_a_noiseless_sensor_leaves_the_remembered_canvas_as_it_was(subject, values) -> None:
    noiseless = RenderSettings(sensor=Sensor().noiseless())
    renderer = ExposureRenderer.for_subject(subject, noiseless)
    images = [render_exposure(renderer, values[4], 0, exposure_noise(0, k, 1)).image for k in range(3)]
    assert renderer.canvases.hits == 2
    assert all(np.array_equal(images[0], image) for image in images[1:])  # quantised from copies


def test_a_pickled_renderer_arrives_with_an_empty_cache(subject, values) -> None:
    renderer = ExposureRenderer.for_subject(subject)
    render_exposure(renderer, values[0], 0, exposure_noise(0, 0, 1))
    copy = pickle.loads(pickle.dumps(renderer))
    assert len(renderer.canvases) == 1 and len(copy.canvases) == 0 and copy.canvases.entries == CANVASES
    assert np.array_equal(render_exposure(copy, values[0], 0, exposure_noise(0, 0, 1)).image,
                          render_exposure(renderer, values[0], 0, exposure_noise(0, 0, 1)).image)
