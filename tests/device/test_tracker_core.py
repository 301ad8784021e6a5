"""The device core alone, bytes in and bytes out, on a hand-set clock: every command rule of docs/protocol.md."""

from __future__ import annotations

import numpy as np
import pytest
from device_helpers import CoreHost, core_device

from eyehil.protocols import (
    Ack,
    Capability,
    Configure,
    DeviceInfo,
    DeviceState,
    ErrorCode,
    ErrorReply,
    Eye,
    EyeSelect,
    Features,
    GetInfo,
    GetStatus,
    GlintFlags,
    Ping,
    Pong,
    PupilFlags,
    Start,
    Status,
    Stimulus,
    Stop,
)


@pytest.fixture
def host():
    core = core_device(rate=250)
    yield CoreHost(core)
    core.close()


def test_device_info_describes_the_scene(host: CoreHost) -> None:
    host.send(GetInfo())
    (info,) = host.messages()
    assert isinstance(info, DeviceInfo)
    assert (info.camera_width, info.camera_height, info.led_count, info.sample_rate_hz) == (640, 480, 2, 250)
    assert Capability.STIMULUS in info.capabilities and Capability.BINOCULAR not in info.capabilities
    assert (info.protocol_min, info.protocol_max, info.max_payload) == (1, 1, 4096)


def test_one_response_per_command_in_order_with_consecutive_seq(host: CoreHost) -> None:
    seqs = [host.send(m) for m in (Ping(7), GetInfo(), GetStatus(), Stop(), Configure(1, 120, EyeSelect.RIGHT))]
    events = host.read()
    assert [type(e.message) for e in events] == [Pong, DeviceInfo, Status, Ack, Ack]
    assert [e.header.seq for e in events] == [0, 1, 2, 3, 4]  # the device counts from 0 at power-up
    assert events[0].message.nonce == 7 and events[0].message.ping_timestamp_us == 5_000
    assert [e.message.acked_seq for e in events[3:]] == seqs[3:]


def test_configure_is_checked_and_atomic(host: CoreHost) -> None:
    host.send(Configure(2, 500, EyeSelect.BOTH))  # binocular on a monocular scene
    host.send(Configure(3, 500, EyeSelect.RIGHT))  # three LEDs
    host.send(Configure(1, 20_000, EyeSelect.RIGHT))  # rate out of range
    refused = host.messages()
    assert [m.code for m in refused] == [ErrorCode.UNSUPPORTED, ErrorCode.INVALID_ARGUMENT, ErrorCode.INVALID_ARGUMENT]
    host.send(GetInfo())
    assert host.messages()[0].sample_rate_hz == 250  # the previous configuration stays
    host.send(Configure(1, 500, EyeSelect.RIGHT))
    host.send(GetInfo())
    ack, info = host.messages()
    assert isinstance(ack, Ack) and info.sample_rate_hz == 500


def test_state_machine_busy_and_idempotent_stop(host: CoreHost) -> None:
    host.send(Stop())
    host.send(Start())
    host.send(Start())
    host.send(Configure(1, 100, EyeSelect.RIGHT))
    host.send(GetStatus())
    ack_stop, ack_start, busy1, busy2, status = host.messages()
    assert isinstance(ack_stop, Ack) and isinstance(ack_start, Ack)
    assert busy1.code == busy2.code == ErrorCode.BUSY
    assert status.state is DeviceState.STREAMING and status.commands_refused == 2


def test_stream_layout_timestamps_and_stop(host: CoreHost) -> None:
    host.send(Configure(2, 250, EyeSelect.RIGHT))
    host.send(Start())
    host.read()
    host.core.clock.now = 40_000  # 40 ms at 250 Hz: exposures at 4, 8, ..., 40 ms
    host.core.poll()
    host.send(Stop())
    host.core.clock.now = 80_000
    host.core.poll()  # nothing after STOP
    events = host.read()
    samples = [e for e in events if isinstance(e.message, Features)]
    assert len(samples) == 10 and isinstance(events[-1].message, Ack)
    assert [e.header.timestamp_us for e in samples] == list(range(4_000, 40_001, 4_000))
    assert [e.message.frame_id for e in samples] == list(range(10))
    for e in samples:
        (eye,) = e.message.eyes
        assert eye.eye is Eye.RIGHT and PupilFlags.DETECTED in eye.flags
        assert [g.led for g in eye.glints] == [0, 1] and all(GlintFlags.VALID in g.flags for g in eye.glints)


def test_start_before_configure_uses_the_defaults(host: CoreHost) -> None:
    host.send(Start())
    host.core.clock.now = 8_000
    host.core.poll()
    _, first, second = host.messages()
    assert len(first.eyes) == 1 and len(first.eyes[0].glints) == 2  # right eye, every LED
    assert second.frame_id == first.frame_id + 1


def test_output_limit_drops_samples_and_leaves_frame_id_gaps() -> None:
    core = core_device(rate=1000)
    core.max_output_bytes = 740  # room for 10 samples of 74 bytes
    host = CoreHost(core)
    host.send(Start())
    host.read()
    core.clock.now = 30_000  # 30 due at once: the 20 oldest are dropped
    assert core.poll() == 10
    samples = host.messages()
    assert [s.frame_id for s in samples] == list(range(20, 30))
    host.send(GetStatus())
    status = host.messages()[0]
    assert (status.samples_dropped, status.samples_sent) == (20, 10)
    core.close()


def test_stimulus_moves_the_subject_after_its_latency() -> None:
    core = core_device(rate=500, latency=0.05)
    host = CoreHost(core)
    host.send(Start())
    centre = core.camera.take(1).batch.centre[0, 0].copy()
    host.send(Stimulus(1, 0.0, 0.0))  # top-left corner: up and to the subject's left
    ack = host.read()[-1].message
    assert isinstance(ack, Ack) and ack.acked_type == Stimulus.TYPE
    before = core.camera.take(20).batch.centre[-1, 0]  # 40 ms: still fixating the centre
    np.testing.assert_allclose(before, centre)
    after = core.camera.take(150).batch.centre[-1, 0]  # 340 ms: saccade done
    assert after[1] < centre[1] - 5  # looking up moves the pupil image up (smaller image y)
    core.close()


@pytest.mark.parametrize("x, y", [(float("nan"), 0.0), (1e6, 0.0), (0.0, -1e4)])
def test_stimulus_out_of_range_is_refused(host: CoreHost, x: float, y: float) -> None:
    host.send(Stimulus(1, x, y))
    (reply,) = host.messages()
    assert isinstance(reply, ErrorReply) and reply.code == ErrorCode.INVALID_ARGUMENT


def test_region_of_interest_hides_features_outside_it(host: CoreHost) -> None:
    host.send(Configure(2, 250, EyeSelect.RIGHT, roi_x=320, roi_y=0, roi_w=320, roi_h=480))  # right half
    host.send(Start())
    host.core.clock.now = 4_000
    host.core.poll()
    sample = host.messages()[-1]
    (eye,) = sample.eyes  # the right eye images on the left half of the sensor
    assert eye.flags == 0 and eye.centre_x == 0.0 and all(g.flags == 0 for g in eye.glints)


def test_sides_option_makes_a_binocular_device() -> None:
    core = core_device(sides="both")
    host = CoreHost(core)
    host.send(GetInfo())
    host.send(Start())
    core.clock.now = 4_000
    core.poll()
    info, _, sample = host.messages()
    assert Capability.BINOCULAR in info.capabilities
    assert [int(e.eye) for e in sample.eyes] == [0, 1] and all(PupilFlags.DETECTED in e.flags for e in sample.eyes)
    assert sample.eyes[0].centre_x < sample.eyes[1].centre_x  # the right eye images on the image's left
    core.close()
