"""Abuse: garbage, broken frames, wrong versions and types, commands out of order, lost and corrupted frames,
hosts that vanish. The device answers with errors and counters and never crashes; the host counts gaps
exactly and never hangs."""

from __future__ import annotations

import numpy as np
import pytest
from device_helpers import CoreHost, DeadLink, FrameFilter, core_device, start_emulator

from eyehil.drivers.client import Tracker, open_tracker
from eyehil.drivers.errors import TrackerTimeoutError
from eyehil.drivers.links import open_link
from eyehil.protocols import ErrorCode, ErrorReply, GetInfo, GetStatus, Start, encode
from eyehil.protocols.cobs import encode as cobs_encode
from eyehil.protocols.header import pack_frame


@pytest.fixture
def host():
    core = core_device()
    yield CoreHost(core)
    core.close()


def _status(host: CoreHost):
    host.send(GetStatus())
    return host.messages()[-1]


def test_random_bytes_then_a_good_command(host: CoreHost) -> None:
    rng = np.random.default_rng(11)
    for _ in range(50):
        host.core.feed(rng.integers(0, 256, int(rng.integers(1, 400))).astype(np.uint8).tobytes())
    host.core.read_available()  # whatever garbage happened to decode as commands got answers; drop them
    host.core.feed(b"\x00")
    host.send(GetInfo())
    assert host.messages()[-1].model == "eyehil virtual tracker"
    status = _status(host)
    assert status.framing_errors + status.crc_errors > 0


def test_truncated_oversized_and_bad_crc_frames_are_only_counted(host: CoreHost) -> None:
    good = encode(GetInfo(), 1, 0)
    host.core.feed(good[:-6] + b"\x00")  # truncated: COBS or length error
    host.core.feed(b"\x11" * 5000 + b"\x00")  # oversized: more than 4133 encoded bytes
    frame = bytearray(pack_frame(GetInfo.TYPE, 2, 0, b""))
    frame[-1] ^= 0xFF
    host.core.feed(cobs_encode(bytes(frame)) + b"\x00")  # wrong CRC
    assert host.core.read_available() == b""  # no reply to any of them
    status = _status(host)
    assert (status.oversized_frames, status.crc_errors, status.framing_errors) == (1, 1, 1)
    assert status.commands_refused == 0


@pytest.mark.parametrize("frame, code, counter", [
    (pack_frame(0x20, 9, 0, b""), ErrorCode.UNKNOWN_MESSAGE_TYPE, "unknown_messages"),
    (pack_frame(0x81, 9, 0, b""), ErrorCode.UNKNOWN_MESSAGE_TYPE, "unknown_messages"),  # a device -> host type
    (pack_frame(GetInfo.TYPE, 9, 0, b"", version=2), ErrorCode.UNSUPPORTED_VERSION, "version_errors"),
    (pack_frame(0x03, 9, 0, b"\x01" * 12), ErrorCode.MALFORMED_PAYLOAD, "malformed_messages"),  # CONFIGURE short
])
def test_refused_frames_get_an_error_naming_them(host: CoreHost, frame: bytes, code: ErrorCode, counter: str) -> None:
    host.core.feed(cobs_encode(frame) + b"\x00")
    (error,) = host.messages()
    assert isinstance(error, ErrorReply) and error.code == code and error.offending_seq == 9
    assert error.offending_type == frame[3]
    status = _status(host)
    assert getattr(status, counter) == 1 and status.commands_refused == 1


def test_payload_length_field_disagreeing_is_malformed(host: CoreHost) -> None:
    frame = bytearray(pack_frame(GetInfo.TYPE, 4, 0, b"\x00\x00"))
    frame[16] = 5  # payload_len 5, two bytes present
    from eyehil.protocols.crc import crc16

    frame[-2:] = crc16(bytes(frame[:-2])).to_bytes(2, "little")
    host.core.feed(cobs_encode(bytes(frame)) + b"\x00")
    (error,) = host.messages()
    assert error.code == ErrorCode.MALFORMED_PAYLOAD


def test_resynchronises_inside_garbage(host: CoreHost) -> None:
    host.core.feed(b"\x05\x45\x48" + encode(GetInfo(), 3, 0))  # a fragment glued before a frame: one lost
    host.core.feed(encode(GetInfo(), 4, 0))
    replies = host.messages()
    assert len(replies) == 1 and replies[0].model  # the damaged merge is dropped, the next frame answered


def test_garbage_over_real_links_never_kills_the_device(device_url) -> None:
    url = device_url()
    raw = open_link(url, timeout=0.0)
    rng = np.random.default_rng(5)
    try:
        raw.write(rng.integers(1, 256, 20_000).astype(np.uint8).tobytes())  # one long oversized frame
        raw.write(rng.integers(0, 256, 5_000).astype(np.uint8).tobytes())
        with Tracker(raw) as tracker:  # the handshake's leading 0x00 ends any partial frame
            status = tracker.status()
            assert status.oversized_frames >= 1
            tracker.start()
            assert tracker.read_sample().eyes
    finally:
        raw.close()


def test_lost_frames_are_reported_exactly(device_url) -> None:
    dropped: list[int] = []

    def lose(index: int, frame: bytes) -> bytes:  # drop samples 40, 47, 54, ... 397
        if 40 <= index < 400 and index % 7 == 5:
            dropped.append(index)
            return b""
        return frame

    link = FrameFilter(open_link(device_url(rate=1000), timeout=0.0), lose)
    with Tracker(link) as tracker:
        tracker.start()
        samples = list(tracker.samples(count=600))
        tracker.stop()
    assert tracker.stats.lost_frames == len(dropped) == 52
    assert sum(s.lost_before for s in samples) == len(dropped)
    assert sum(s.skipped_before for s in samples) == len(dropped)  # every lost frame was a sample


def test_corrupted_frames_count_as_crc_errors_and_gaps(device_url) -> None:
    corrupted: list[int] = []

    def corrupt(index: int, frame: bytes) -> bytes:
        if 20 <= index < 400 and index % 11 == 0:
            corrupted.append(index)
            return frame[:30] + bytes([(frame[30] ^ 0x02) or 0x03]) + frame[31:]  # never 0x00
        return frame

    link = FrameFilter(open_link(device_url(rate=1000), timeout=0.0), corrupt)
    with Tracker(link) as tracker:
        tracker.start()
        list(tracker.samples(count=500))
        tracker.stop()
    assert tracker.stats.crc_errors + tracker.stats.framing_errors == len(corrupted) == 35
    assert tracker.stats.lost_frames == len(corrupted)


def test_lost_ack_is_retried_and_busy_start_counts_as_started(device_url) -> None:
    state = {"acks_dropped": 0}

    def lose_first_start_ack(index: int, frame: bytes) -> bytes:
        if index == 2 and state["acks_dropped"] == 0:  # DEVICE_INFO, STATUS, then the START's ACK
            state["acks_dropped"] = 1
            return b""
        return frame

    link = FrameFilter(open_link(device_url(), timeout=0.0), lose_first_start_ack)
    with Tracker(link) as tracker:
        tracker.start()  # ACK lost -> resent -> BUSY -> treated as started
        assert tracker.streaming and tracker.read_sample()
    assert tracker.stats.retries == 1 and state["acks_dropped"] == 1


def test_host_never_hangs_on_a_silent_device() -> None:
    dead = DeadLink()
    with pytest.raises(TrackerTimeoutError):
        Tracker(dead, response_timeout=0.05, retries=2)
    # three attempts, and the host asked to wait no longer than their three response deadlines in all (what the
    # host decided, not how long a busy machine took to run it)
    assert dead.written.count(b"\x00") >= 3 and 0 < dead.waited_s <= 3 * 0.05 + 1e-9


def test_host_disconnects_and_reconnects_mid_stream() -> None:
    for backend in ("pty", "tcp"):
        url, close = start_emulator(backend, rate=500)
        try:
            first = open_tracker(url)
            first.start()
            first.read_sample()
            first.close(stop=False)  # vanish mid-stream
            with open_tracker(url) as second:
                # a pty cannot tell hosts apart: the device kept streaming; a new TCP connection is a fresh session
                assert second.streaming is (backend == "pty")
                second.stop()
                second.drain()
                second.start()
                samples = list(second.samples(count=100))
                assert second.stats.lost_frames == 0 and len(samples) == 100
            status_after = open_tracker(url)
            assert not status_after.streaming  # the second host stopped its stream when it closed
            status_after.close()
        finally:
            close()


def test_start_refused_while_streaming_reports_busy() -> None:
    core = core_device()
    host = CoreHost(core)
    host.send(Start())
    host.send(Start())
    _, busy = host.messages()
    assert busy.code == ErrorCode.BUSY
    core.close()
