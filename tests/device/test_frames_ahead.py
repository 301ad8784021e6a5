"""Frames rendered ahead of the link (issue 16): the render pool, the bounded render-ahead queue of the device core,
and the fast clock's rule for frame streams (`VirtualTracker.fast_room`), on a hand-set clock with explicit waits
for the renders (docs/frames.md, "Frames on the links")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from device_helpers import CoreHost

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.clock import ManualClock
from eyehil.emulator.device.frame_stream import FrameOptions
from eyehil.emulator.device.frames import ExposureRenderer
from eyehil.emulator.device.links.base import FAST_LOW_WATER
from eyehil.emulator.device.render_pool import RenderJob, RenderPool, render_job
from eyehil.emulator.device.tracker import VirtualTracker
from eyehil.protocols import Ack, Configure, EyeSelect, FrameChunk, GetStatus, Start, Stop, StreamSelect
from eyehil.protocols.images import ImageAssembler

PERIOD_US = 4_000  # 250 Hz


@pytest.fixture(scope="module", autouse=True)
def _resource_tracker() -> None:
    """multiprocessing's resource tracker (one per process, for the process pool's locks) keeps a pipe open for the
    life of the test process: start it before the per-test leak check looks."""
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()


def _core(workers: int = 0, ahead: int = 4, stream: StreamSelect = StreamSelect.FRAMES) -> CoreHost:
    """A started monocular device (guestrin2006, demo script) on a manual clock at time 0."""
    frames = FrameOptions(workers=workers, ahead=ahead, kind="thread")
    core = VirtualTracker(build_subject(DeviceOptions(script="demo")), ManualClock(), frames=frames)
    host = CoreHost(core)
    host.send(Configure(2, 250, EyeSelect.RIGHT, stream))
    host.send(Start())
    assert all(isinstance(m, Ack) for m in host.messages())
    return host


def _drain(host: CoreHost) -> list:
    """Everything the core releases while the host reads all (the link empty at each poll)."""
    out = []
    while True:
        host.core.poll(backlog=0)
        got = host.messages()
        if not got:
            return out
        out += got


def _images(messages: list) -> dict[int, np.ndarray]:
    assembler, images = ImageAssembler(), {}
    for m in messages:
        if isinstance(m, FrameChunk) and (image := assembler.add(m)) is not None:
            images[image.frame_id] = image.pixels
    return images


def _status(host: CoreHost):
    host.send(GetStatus())
    return host.messages()[0]


def test_exposures_render_ahead_in_order_with_the_pixels_of_the_device_thread() -> None:
    pooled, inline = _core(workers=2, ahead=4), _core(workers=0)
    try:
        pooled.core.poll(5 * PERIOD_US, backlog=0)  # five exposures at once: four places, the oldest dropped
        assert pooled.core.frames.wait_rendered(timeout=120)
        messages = pooled.messages() + _drain(pooled)
        ids = [m.frame_id for m in messages if isinstance(m, FrameChunk)]
        assert ids == sorted(ids) and sorted(set(ids)) == [1, 2, 3, 4]
        expected = {}
        for k in range(5):  # the device thread's render of the same exposures, one per poll
            inline.core.poll((k + 1) * PERIOD_US, backlog=0)
            expected |= _images(inline.messages() + _drain(inline))
        got = _images(messages)
        assert sorted(got) == [1, 2, 3, 4] and all(np.array_equal(got[i], expected[i]) for i in got)
        status = _status(pooled)
        assert (status.frames_sent, status.frames_dropped) == (4, 1)
    finally:
        pooled.core.close()
        inline.core.close()


def test_the_render_ahead_queue_is_bounded_and_its_drops_counted() -> None:
    host = _core(workers=2, ahead=3)
    try:
        core = host.core
        budget = core.frames.options.budget_bytes
        for k in range(6):  # one exposure per poll while nothing can leave (the link is full)
            core.poll((k + 1) * PERIOD_US, backlog=budget)
        assert core.frames.wait_rendered(timeout=120)
        assert core.frames.room == 0 and not core.fast_room(0)
        assert host.messages() == []  # the link is full: nothing released
        assert (_status(host).frames_dropped, core.frames.sent) == (3, 0)  # exposures 3, 4, 5 had no place
        _drain(host)
        assert core.frames.room == 3 and core.fast_room(0) and _status(host).frames_sent == 3
    finally:
        host.core.close()


def test_stop_abandons_images_rendering_and_waiting() -> None:
    host = _core(workers=1, ahead=4)
    try:
        host.core.poll(3 * PERIOD_US, backlog=host.core.frames.options.budget_bytes)
        host.send(Stop())
        host.messages()
        status = _status(host)
        assert (status.frames_sent, status.frames_dropped) == (0, 3)
    finally:
        host.core.close()


def test_the_fast_clock_rule_for_frames_is_the_render_queue_and_the_frame_budget_not_8_kilobytes() -> None:
    features, frames = _core(stream=StreamSelect.FEATURES), _core(workers=0)
    try:
        assert features.core.fast_room(FAST_LOW_WATER - 1) and not features.core.fast_room(FAST_LOW_WATER)
        core, budget = frames.core, frames.core.frames.options.budget_bytes
        assert core.fast_room(10 * FAST_LOW_WATER)  # the next image renders while the link carries 80 kB
        assert not core.fast_room(budget)
        core.poll(PERIOD_US, backlog=budget)  # rendered on the device's thread; its chunks wait in the core
        assert core.frames.room == 0 and not core.fast_room(0)
        frames.messages()
        core.poll(backlog=0)
        assert frames.messages() and core.frames.room == 1 and core.fast_room(0)
    finally:
        features.core.close()
        frames.core.close()


@pytest.mark.parametrize("kind", ["thread", "process"])
def test_pool_workers_render_the_same_pixels_as_the_caller(kind: str) -> None:
    subject = build_subject(DeviceOptions(scene="blignaut2014", script="demo"))
    try:
        renderer = ExposureRenderer.for_subject(subject)
        rows = subject.observe(np.array([1_000_000, 2_500_000])).values
        jobs = [RenderJob(7, 1, rows[0], seed=3, leds=1, eye_index=1),
                RenderJob(8, 3, rows[1], seed=3, region=(400, 300, 640, 480), eye_indices=(0, 1), fmt="jpeg")]
        with RenderPool(renderer, 1, kind) as pool:
            futures = [pool.submit(job) for job in jobs]
            got = [f.result(timeout=120) for f in futures]
        for job, rendered in zip(jobs, got, strict=True):
            want = render_job(renderer, job)
            assert np.array_equal(rendered.image, want.image) and rendered.roi_xy == want.roi_xy
            assert rendered.encoded == want.encoded
        only = replace(jobs[1], pixels=False)  # the ZeroMQ facade's jobs: the encoding alone crosses the pipe
        with RenderPool(renderer, 1, kind) as pool:
            bare = pool.submit(only).result(timeout=120)
        assert bare.image is None and bare.encoded == got[1].encoded and bare.roi_xy == got[1].roi_xy
    finally:
        subject.close()


def test_frame_options_refuse_unbounded_queues() -> None:
    with pytest.raises(ValueError):
        FrameOptions(ahead=0)
    with pytest.raises(ValueError):
        FrameOptions(ahead=100_000)
    with pytest.raises(ValueError):
        DeviceOptions(render_workers=99)
