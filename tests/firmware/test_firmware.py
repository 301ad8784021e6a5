"""Firmware in the loop: the C reference firmware (firmware_stubs/), built here, runs with its UART on a
pseudo-terminal and its camera backed by the emulator's sensor; the host driver talks to it as to any tracker.

- its codecs pass the unit tests against the golden wire vectors;
- handshake, CONFIGURE, START, FEATURES, STOP: the features equal those the Python device's camera computes for
  the same exposures, to the float32 the wire carries;
- CONFIGURE is refused exactly as `eyehil.protocols.native.check_configure` refuses it;
- bad input (garbage, wrong CRC, unknown types, wrong versions, short payloads ...) gets the same answers and
  counters from the C firmware as from the Python `VirtualTracker`;
- STIMULUS reaches the simulated subject, and a position the emulator cannot show is refused.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from firmware_helpers import GOLDEN, exchange_raw

from eyehil.drivers.client import Tracker, open_tracker
from eyehil.drivers.errors import CommandRefusedError
from eyehil.drivers.links import open_link
from eyehil.emulator.device.build import build_device, build_subject, options_from_query
from eyehil.emulator.device.camera import Camera, Selection
from eyehil.protocols import Configure, ErrorCode, ErrorReply, GetInfo, GetStatus, Start, Stop, encode
from eyehil.protocols.cobs import encode as cobs_encode
from eyehil.protocols.crc import crc16
from eyehil.protocols.enums import Capability, DeviceState, Eye, EyeSelect, StreamSelect
from eyehil.protocols.header import MessageType, pack_frame
from eyehil.protocols.native import DEVICE_TYPES, check_configure
from eyehil.protocols.stream import NativeReceiver, Received

RATE_HZ = 500
SCENES = {  # scene -> (sensor px, LEDs, eyes seen)
    "guestrin2006": ((640, 480), 2, (Eye.RIGHT,)),
    "blignaut2014": ((1600, 1200), 1, (Eye.RIGHT, Eye.LEFT)),
}


def test_codec_unit_tests_pass_against_the_golden_vectors(firmware_build) -> None:
    result = subprocess.run([str(firmware_build.unit_tests), str(GOLDEN)], capture_output=True, text=True,
                            timeout=30, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert ", 0 failed" in result.stdout


@pytest.mark.parametrize("scene", SCENES)
def test_handshake_reports_the_emulated_camera(rig, scene: str) -> None:
    sensor, leds, eyes = SCENES[scene]
    with open_tracker(rig(scene=scene).url) as tracker:
        info = tracker.info
        sync = tracker.sync_clock(pings=4)
        status = tracker.status()
    assert (info.model, info.firmware_version, info.protocol_min, info.protocol_max) == (
        "eyehil reference firmware", "0.1.0", 1, 1)
    assert (info.camera_width, info.camera_height, info.led_count) == (*sensor, leds)
    assert (info.min_rate_hz, info.max_rate_hz, info.sample_rate_hz, info.max_payload) == (30, 2000, 250, 4096)
    expected = Capability.FEATURES | Capability.ROI | Capability.TIME_SYNC | Capability.STIMULUS
    assert info.capabilities == expected | (Capability.BINOCULAR if len(eyes) == 2 else 0)
    assert 0 < sync.rtt_us < 100_000
    assert status.state is DeviceState.IDLE and status.commands_refused == 0


def _reference(options: dict, frame_ids: np.ndarray, t0_us: int, eyes: tuple[Eye, ...], leds: int):
    """What the Python device's camera (`eyehil.emulator.device.camera.Camera`) reports for exposures `frame_ids` of a
    stream started at `t0_us` on a fresh subject."""
    scene_sensor, _, tracked = SCENES[options["scene"]]
    camera = Camera(build_subject(options_from_query("&".join(f"{k}={v}" for k, v in options.items())),
                                  appearance=False), scene_sensor, tracked)
    try:
        camera.start(t0_us, RATE_HZ, Selection(eyes, leds))
        exposures = camera.take(int(frame_ids.max()) + 1)
    finally:
        camera.subject.close()
    return exposures.time_us[frame_ids], {k: getattr(exposures.batch, k)[frame_ids] for k in
                                          ("flags", "centre", "axes", "angle_deg", "confidence", "glint_xy",
                                           "glint_flags")}


def _received(samples) -> dict[str, np.ndarray]:
    """The FEATURES fields of `samples` as arrays shaped like `camera.detect`'s."""
    eyes = [s.eyes for s in samples]
    return {
        "flags": np.array([[int(e.flags) for e in s] for s in eyes]),
        "centre": np.array([[(e.centre_x, e.centre_y) for e in s] for s in eyes]),
        "axes": np.array([[(e.axis_a, e.axis_b) for e in s] for s in eyes]),
        "angle_deg": np.array([[e.angle_deg for e in s] for s in eyes]),
        "confidence": np.array([[e.confidence for e in s] for s in eyes]),
        "glint_xy": np.array([[[(g.x, g.y) for g in e.glints] for e in s] for s in eyes]),
        "glint_flags": np.array([[[int(g.flags) for g in e.glints] for e in s] for s in eyes]),
    }


@pytest.mark.parametrize("scene", SCENES)
def test_streamed_features_equal_the_emulators_for_the_same_exposures(rig, scene: str) -> None:
    # fixations, saccades, a blink: exact and interpolated features; the fast clock (lockstep with this host), so
    # that no exposure is lost however busy the machine (real time: python -m bench firmware_stream)
    options = {"scene": scene, "script": "demo", "clock": "fast"}
    with open_tracker(rig(**options).url) as tracker:
        tracker.configure(rate_hz=RATE_HZ)
        tracker.start()
        samples = list(tracker.samples(count=600))
        tracker.stop()
        samples += tracker.drain()  # sent before the STOP's ACK
        status = tracker.status()
        assert tracker.drain() == []  # nothing streamed after the ACK (it would have come before the STATUS)
    frame_ids = np.array([s.frame_id for s in samples])
    np.testing.assert_array_equal(frame_ids, np.arange(len(samples)))  # none lost, first stream since power-up
    assert status.samples_sent == len(samples) and status.samples_dropped == 0
    _, leds, eyes = SCENES[scene]
    t0 = samples[0].device_us - 1_000_000 // RATE_HZ
    times, expected = _reference(options, frame_ids, t0, eyes, leds)
    np.testing.assert_array_equal([s.device_us for s in samples], times)
    got = _received(samples)
    for name, values in expected.items():
        want = values if name.endswith("flags") else values.astype(np.float32)  # the wire's one rounding
        np.testing.assert_array_equal(got[name], want, err_msg=name)
    assert np.ptp(got["centre"][..., 0]) > 5.0  # the eyes moved: interpolated samples were compared too


CONFIGURE_CASES = [
    Configure(1, 500, EyeSelect.RIGHT), Configure(2, 30, EyeSelect.RIGHT), Configure(2, 2000, EyeSelect.LEFT),
    Configure(0, 250, EyeSelect.RIGHT), Configure(3, 250, EyeSelect.RIGHT), Configure(2, 29, EyeSelect.RIGHT),
    Configure(2, 2001, EyeSelect.RIGHT), Configure(2, 250, EyeSelect(0)), Configure(2, 250, EyeSelect(4)),
    Configure(2, 250, EyeSelect.BOTH), Configure(2, 250, EyeSelect.RIGHT, StreamSelect(0)),
    Configure(2, 250, EyeSelect.RIGHT, StreamSelect(4)), Configure(2, 250, EyeSelect.RIGHT, StreamSelect.FRAMES),
    Configure(2, 250, EyeSelect.RIGHT, StreamSelect.FEATURES, 0, 0, 640, 480),
    Configure(2, 250, EyeSelect.RIGHT, StreamSelect.FEATURES, 1, 0, 640, 480),
    Configure(2, 250, EyeSelect.RIGHT, StreamSelect.FEATURES, 10, 0, 0, 0),
    Configure(2, 250, EyeSelect.RIGHT, StreamSelect.FEATURES, 0, 0, 0, 5),
    Configure(1, 250, EyeSelect.RIGHT, StreamSelect.FEATURES, 100, 100, 320, 240),
]


def _random_configures(n: int, rng: np.random.Generator) -> list[Configure]:
    """Configurations around every boundary of the CONFIGURE rules."""
    def pick(values):
        return int(rng.choice(values))

    return [Configure(pick([0, 1, 2, 3]), pick([0, 29, 30, 250, 2000, 2001, 65535]), EyeSelect(pick([0, 1, 2, 3, 5])),
                      StreamSelect(pick([0, 1, 2, 3, 8])), pick([0, 0, 1, 320, 639, 640]), pick([0, 0, 1, 479, 480]),
                      pick([0, 0, 1, 320, 640]), pick([0, 0, 1, 240, 480])) for _ in range(n)]


def test_configure_is_refused_as_the_python_rules_say(rig) -> None:
    with open_tracker(rig(scene="guestrin2006").url) as tracker:
        for cfg in CONFIGURE_CASES + _random_configures(60, np.random.default_rng(3)):
            expected = check_configure(cfg, tracker.info)
            try:
                tracker.command(cfg)
                got = None
            except CommandRefusedError as exc:
                got = exc.code
            assert got == (None if expected is None else expected[0]), cfg
            if got is None:
                assert tracker.command(GetInfo()).sample_rate_hz == cfg.rate_hz  # reported at once
        tracker.configure(leds=1, rate_hz=RATE_HZ)
        tracker.start()
        for command in (Configure(1, RATE_HZ, EyeSelect.RIGHT), Start()):
            with pytest.raises(CommandRefusedError) as busy:
                tracker.command(command)
            assert busy.value.code == ErrorCode.BUSY
        assert len(tracker.read_sample().eyes[0].glints) == 1  # the accepted configuration was applied
        tracker.stop()
        tracker.command(Stop())  # idempotent


def _with_crc(frame: bytes) -> bytes:
    """`frame` with its CRC recomputed."""
    return frame[:-2] + crc16(frame[:-2]).to_bytes(2, "little")


def _bad_input() -> bytes:
    """A byte stream of every kind of bad input, each kind once, then some garbage."""
    good = encode(GetInfo(), 1, 0)
    bad_crc = bytearray(pack_frame(GetInfo.TYPE, 2, 0, b""))
    bad_crc[-1] ^= 0xFF
    long_len = bytearray(pack_frame(GetInfo.TYPE, 8, 0, b"\x00\x00"))
    long_len[16] = 5
    frames = [
        pack_frame(0x20, 3, 0, b""),  # unknown type
        pack_frame(0x81, 4, 0, b""),  # a device -> host type
        pack_frame(GetInfo.TYPE, 5, 0, b"", version=2),
        pack_frame(0x03, 6, 0, b"\x01" * 12),  # CONFIGURE one byte short
        pack_frame(0x01, 7, 0, b""),  # PING without its nonce
        _with_crc(bytes(long_len)),  # payload_len disagrees with the frame
        _with_crc(b"XH" + pack_frame(GetInfo.TYPE, 9, 0, b"")[2:]),  # bad magic, good CRC
        bytes(bad_crc),
        b"\x45\x48\x01\x02\x01",  # shorter than a header
    ]
    garbage = np.random.default_rng(11).integers(0, 256, 3000).astype(np.uint8).tobytes()
    return (good[:-6] + b"\x00" + b"\x11" * 5000 + b"\x00" + b"".join(cobs_encode(f) + b"\x00" for f in frames)
            + b"\x05\x45\x48" + good + garbage + b"\x00")


def _python_device_answers(data: bytes) -> list[Received]:
    """What the Python `VirtualTracker` answers to `data`."""
    core = build_device(options_from_query("clock=fast"))
    try:
        core.feed(data)
        return [e for e in NativeReceiver(accept=DEVICE_TYPES).feed(core.read_available()) if isinstance(e, Received)]
    finally:
        core.close()


def _summary(replies: list[Received]) -> list[tuple]:
    """Type, and for errors code, offending seq and type, of each reply (timestamps and texts differ)."""
    out = []
    for r in replies:
        m = r.message
        out.append((r.header.msg_type, m.code, m.offending_seq, m.offending_type) if isinstance(m, ErrorReply)
                   else (r.header.msg_type,))
    return out


def test_bad_input_gets_the_same_answers_and_counters_as_the_python_device(rig) -> None:
    data = _bad_input() + encode(GetStatus(), 99, 0)
    link = open_link(rig(scene="guestrin2006").url, timeout=0.0)
    try:
        got = exchange_raw(link, data, MessageType.STATUS)
        with Tracker(link) as tracker:  # and the firmware talks normally afterwards
            assert tracker.info.model == "eyehil reference firmware"
    finally:
        link.close()
    expected = _python_device_answers(data)
    assert _summary(got) == _summary(expected)
    counters = ("rx_frames", "tx_frames", "crc_errors", "framing_errors", "oversized_frames", "unknown_messages",
                "version_errors", "malformed_messages", "commands_refused")
    status, reference = got[-1].message, expected[-1].message
    assert {c: getattr(status, c) for c in counters} == {c: getattr(reference, c) for c in counters}
    assert status.crc_errors >= 1 and status.framing_errors >= 3 and status.oversized_frames == 1
    assert status.unknown_messages == 2 and status.version_errors == 1 and status.malformed_messages == 3


def test_stimulus_reaches_the_simulated_subject(rig) -> None:
    firmware = rig(scene="guestrin2006")
    with open_tracker(firmware.url) as tracker:
        ack_us = tracker.stimulus(7, 100.0, 50.5)
        tracker.stimulus(8, 120.0, 60.0, visible=False)
        for x, y in ((float("nan"), 10.0), (1e6, 10.0), (10.0, -1e4)):
            with pytest.raises(CommandRefusedError) as refused:
                tracker.stimulus(9, x, y)
            assert refused.value.code == ErrorCode.INVALID_ARGUMENT and "STIMULUS" in refused.value.text
    (t_us, *fields), hidden = firmware.sensor.stimuli
    assert fields == [7, 100.0, 50.5, 1] and 0 < t_us <= ack_us  # received, forwarded, then acknowledged
    assert hidden[1:] == (8, 120.0, 60.0, 0)
