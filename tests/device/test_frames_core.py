"""Frames on the device core (hand-set clock, bytes in and out), a region of interest as one image, the appearance
channels, and `eyehil stream --frames` (docs/frames.md, docs/protocol.md section 5.3)."""

from __future__ import annotations

import numpy as np
from device_helpers import CoreHost, core_device, query, start_emulator

from eyehil.cli import main
from eyehil.drivers.client import open_tracker
from eyehil.drivers.frames import FrameReader
from eyehil.emulator.device.appearance import AppearanceSolver
from eyehil.emulator.device.solver import FeatureSolver
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.scene import load_scene
from eyehil.protocols import (
    Ack,
    Capability,
    Configure,
    Eye,
    EyeSelect,
    Features,
    FrameChunk,
    GetInfo,
    GetStatus,
    PupilFlags,
    Start,
    Stop,
    StreamSelect,
)


def _streaming(rate: int = 250) -> CoreHost:
    """A monocular device core (guestrin2006) streaming FEATURES and frames of the right eye, started at time 0."""
    host = CoreHost(core_device(rate=rate))
    host.send(Configure(2, rate, EyeSelect.RIGHT, StreamSelect.BOTH))
    host.send(Start())
    assert all(isinstance(m, Ack) for m in host.messages())
    return host


def test_the_device_advertises_frames() -> None:
    host = CoreHost(core_device())
    host.send(GetInfo())
    assert Capability.FRAMES in host.messages()[0].capabilities
    host.core.close()


def test_features_pass_waiting_chunks_and_images_that_cannot_start_are_dropped() -> None:
    host = _streaming()
    core, full = host.core, host.core.frames.options.budget_bytes
    core.clock.now = 4_000  # exposure 0; the link is full: its FEATURES go out, its image waits in the core
    core.poll(backlog=full)
    assert [type(m) for m in host.messages()] == [Features]
    core.clock.now = 8_000  # exposure 1: FEATURES again; its image is dropped, since exposure 0's still waits
    core.poll(backlog=full)
    assert [(type(m), m.frame_id) for m in host.messages()] == [(Features, 1)]
    core.poll(backlog=0)  # nothing due, the link drained: exposure 0's image goes
    chunks = host.messages()
    assert chunks and all(isinstance(m, FrameChunk) and m.frame_id == 0 and m.eye == Eye.RIGHT for m in chunks)
    assert (chunks[0].width, chunks[0].height, len(chunks)) == (320, 240, chunks[0].chunk_count)
    host.send(GetStatus())
    status = host.messages()[0]
    assert (status.samples_sent, status.samples_dropped, status.frames_sent, status.frames_dropped) == (2, 0, 1, 1)
    core.close()


def test_stop_abandons_a_waiting_image() -> None:
    host = _streaming()
    host.core.clock.now = 4_000
    host.core.poll(backlog=host.core.frames.options.budget_bytes)
    host.messages()
    host.send(Stop())
    host.send(GetStatus())
    ack, status = host.messages()  # nothing streamed after the ACK
    assert isinstance(ack, Ack) and (status.frames_sent, status.frames_dropped) == (0, 1)
    host.core.close()


def test_a_region_of_interest_is_one_image_of_both_eyes() -> None:
    """blignaut2014's pupils lie near (600, 620) and (1000, 620) px: the region holds both."""
    url, close = start_emulator("loop", scene="blignaut2014", rate=100)
    try:
        with open_tracker(url) as tracker:
            tracker.configure(stream=StreamSelect.BOTH, roi=(400, 500, 800, 240))
            reader = FrameReader(tracker)
            tracker.start()
            detected = list(reader.samples(count=5))
            tracker.stop()
            streamed = {s.frame_id: s for s in tracker.drain()}
    finally:
        close()
    image = reader.last_images[0].image
    assert (image.eye, image.roi_x, image.roi_y, image.pixels.shape) == (Eye.BOTH, 400, 500, (240, 800))
    for sample in detected:
        truth = streamed[sample.frame_id]
        for found, want in zip(sample.eyes, truth.eyes, strict=True):
            assert found.eye == want.eye and PupilFlags.DETECTED in found.flags
            assert np.hypot(found.centre_x - want.centre_x, found.centre_y - want.centre_y) < 0.1


def test_appearance_channels_extend_the_features_unchanged() -> None:
    """`AppearanceSolver` computes the feature channels itself (one forward-model call): they must stay those of
    `FeatureSolver`."""
    eye, scene = normative_eye("navarro"), load_scene("blignaut2014")
    xy = np.array([[0.0, 0.0], [120.0, -60.0]])
    plain, extended = FeatureSolver(eye, scene).solve(xy), AppearanceSolver(eye, scene).solve(xy)
    np.testing.assert_array_equal(extended[..., : plain.shape[-1]], plain)
    assert extended.shape[-1] == AppearanceSolver(eye, scene).layout.total > plain.shape[-1]


def test_stream_frames_saves_pngs(tmp_path, capsys) -> None:
    url = f"loop://?{query(scene='blignaut2014', rate=100)}"
    assert main(["stream", url, "--frames", "--duration", "0.1", "--every", "5", "--save", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    printed = out.count("right pupil (")  # every 5th sample (the fast clock may drop a few images at first)
    assert printed >= 2 and out.count("left pupil (") == printed and "images" in out
    names = sorted(p.name for p in tmp_path.iterdir())
    assert len(names) == 2 * printed and all(n.startswith("frame_") and n.endswith(".png") for n in names)
