"""The link-rate option (issue 16): rate texts, the token bucket and `PacedLink` on a manual clock (no wall-clock
waits), and a device streaming frames through a full-speed USB rate: the host receives what the real link carries
and the device counts the images that did not fit (docs/frames.md, "Link rate")."""

from __future__ import annotations

import argparse

import pytest

from eyehil.emulator.device.build import DeviceOptions, build_subject, paced
from eyehil.emulator.device.cli import options as cli_options
from eyehil.emulator.device.cli import register
from eyehil.emulator.device.clock import FastClock, ManualClock
from eyehil.emulator.device.links.loop import open_loop
from eyehil.emulator.device.links.paced import MAX_PACED_BACKLOG, PacedLink, Pacer, parse_link_rate
from eyehil.emulator.device.tracker import VirtualTracker
from eyehil.protocols import Configure, EyeSelect, FrameChunk, GetStatus, Start, Status, StreamSelect
from eyehil.protocols.native import DEVICE_TYPES, encode
from eyehil.protocols.stream import NativeReceiver, Received


class FakeLink:
    """A DeviceLink that takes everything at once and remembers it."""

    name, url, connected = "fake", "fake://", True

    def __init__(self) -> None:
        self.data = bytearray()
        self.reset = None

    def attach(self, receive, reset) -> None:
        self.reset = reset

    def send(self, data: bytes) -> None:
        self.data += data

    def backlog(self) -> int:
        return 0

    def close(self) -> None:
        pass


@pytest.mark.parametrize(("text", "bytes_per_s"), [
    ("12Mbit", 1_500_000), ("12 Mbit/s", 1_500_000), ("1MB", 1_000_000), ("2.5kB", 2500), ("115200baud", 11_520),
    ("9600 baud", 960), ("4096", 4096), ("usb-fs", 1_216_000), ("USB-HS", 53_248_000), ("1Gbit", 125_000_000)])
def test_rate_texts(text: str, bytes_per_s: int) -> None:
    assert parse_link_rate(text) == bytes_per_s


@pytest.mark.parametrize("text", ["", "fast", "12 parsecs", "-5MB", "1bit", "20GB", "12Mbps", "nan"])
def test_bad_rate_texts_are_refused(text: str) -> None:
    with pytest.raises(ValueError):
        parse_link_rate(text)


def test_the_bucket_admits_the_rate_exactly_and_stores_one_granule_when_idle() -> None:
    pacer = Pacer(1_216_000, start_us=0)  # usb-fs: 1216 bytes per 1 ms frame
    assert pacer.burst == 1216 and pacer.admit(0, 10_000) == 0
    assert pacer.admit(500, 10_000) == 608
    assert pacer.admit(1_000, 10_000) == 608
    assert pacer.admit(1_000_000, 10_000) == 10_000  # busy for a second: all of it was carried
    assert pacer.admit(2_000_000, 10_000) == 1216  # then idle: one frame's worth stored, not a second's
    assert pacer.admit(2_000_250, 100) == 100 and pacer.admit(2_000_250, 10_000) == 204
    assert pacer.due_us(2_000_250, 1216) == 2_001_250
    slow = Pacer(11_520, start_us=0)  # 115200 baud: 11.52 bytes per ms, fractions carried exactly
    assert sum(slow.admit(t, 10**6) for t in range(1000, 1_000_001, 1000)) == 11_520


def test_a_paced_link_hands_on_the_rate_of_device_time_and_counts_what_it_cannot_hold() -> None:
    clock, inner = ManualClock(), FakeLink()
    link = PacedLink(inner, 100_000, clock)  # 100 bytes per ms
    resets = []
    link.attach(lambda data: None, lambda: resets.append(1))
    link.send(b"x" * 1000)
    assert (len(inner.data), link.backlog(), link.wake_delay_s()) == (0, 1000, 0.001)
    for _ in range(4):
        clock.advance(1000)
        link.pump()
    assert (len(inner.data), link.backlog()) == (400, 600)
    clock.advance(1_000_000)  # a runner woken late: the busy link carried the rest meanwhile
    link.pump()
    assert (len(inner.data), link.backlog()) == (1000, 0)
    clock.advance(1_000_000)  # idle for a second: one granule stored, not a second's worth
    link.send(b"z" * 1000)
    assert (len(inner.data), link.backlog()) == (1100, 900)
    link.send(b"y" * MAX_PACED_BACKLOG)
    assert link.bytes_dropped == MAX_PACED_BACKLOG and link.backlog() == 900
    inner.reset()  # a new host: what waits is forgotten
    assert link.backlog() == 0 and resets == [1] and link.wake_delay_s() is None
    link.close()


def test_a_device_streaming_frames_over_full_speed_usb_meets_its_bandwidth() -> None:
    """One simulated second at 250 Hz, FEATURES and 320 x 240 images (19 MB/s of images asked for) through 1.2 MB/s:
    every FEATURES sample arrives, the bytes never exceed the rate, and the images that did not fit are counted."""
    clock = ManualClock()
    core = VirtualTracker(build_subject(DeviceOptions()), clock)
    inner = FakeLink()
    link = paced(inner, DeviceOptions(link_rate="usb-fs"), clock)
    link.attach(lambda data: None, lambda: None)
    seq = 0
    for message in (Configure(2, 250, EyeSelect.RIGHT, StreamSelect.BOTH), Start()):
        seq += 1
        core.feed(encode(message, seq, 0))
    step_us, rate = 250, 1_216_000
    for t in range(step_us, 1_000_001, step_us):  # what the runner does at each wake-up, on simulated time
        clock.push(t)
        core.poll(backlog=link.backlog())
        link.send(core.read_available())
        link.pump()
        assert len(inner.data) <= rate * t // 1_000_000 + link.pacer.burst
    core.feed(encode(GetStatus(), seq + 1, 0))
    link.send(core.read_available())
    events = NativeReceiver(accept=DEVICE_TYPES).feed(bytes(inner.data))
    messages = [e.message for e in events if isinstance(e, Received)]
    assert len(inner.data) >= 0.95 * rate  # the link was kept busy
    chunks = [m for m in messages if isinstance(m, FrameChunk)]
    whole = sum(c.chunk_index == c.chunk_count - 1 for c in chunks)
    assert 10 <= whole <= rate // (320 * 240)  # about 15 images per second fit, not 250
    clock.advance(10_000_000)
    link.pump()
    status = NativeReceiver(accept=DEVICE_TYPES).feed(bytes(inner.data[-4096:]))
    status = [e.message for e in status if isinstance(e, Received) and isinstance(e.message, Status)]
    assert status and status[-1].samples_dropped == 0 and status[-1].frames_dropped >= 200
    core.close()


def test_a_reply_goes_out_on_a_lockstep_clock_and_its_transmission_takes_device_time() -> None:
    """`eyehil emulate --clock fast --link-rate usb-fs` never answered GET_INFO: its clock moves only when pushed,
    nothing streamed to push it, and the pacer waited for device time that never came. The pump now pushes the
    clock to when the waiting bytes have gone (and the runner need not sleep for them)."""
    clock = FastClock(wall_floor=False)
    inner = FakeLink()
    link = PacedLink(inner, 1_216_000, clock)
    link.attach(lambda data: None, lambda: None)
    link.send(b"x" * 5000)  # a reply several 1 ms frames long
    assert bytes(inner.data) == b"x" * 5000 and link.waiting == 0 and link.wake_delay_s() is None
    assert clock.now_us() == -(-5000 * 1_000_000 // 1_216_000)  # 4.112 ms at 1,216,000 B/s
    link.send(b"y" * 100)
    assert len(inner.data) == 5100 and link.backlog() == 0
    link.close()


def test_the_option_reaches_the_command_line_and_is_refused_where_it_means_nothing() -> None:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(["emulate", "--link", "tcp", "--link-rate", "115200baud", "--render-workers", "2"])
    opts = cli_options(args)
    assert (opts.link_rate, opts.render_workers) == ("115200baud", 2)
    with pytest.raises(ValueError):
        DeviceOptions(link_rate="fast")
    with pytest.raises(ValueError):
        open_loop("loop://?link_rate=usb-fs")
    assert paced(FakeLink(), DeviceOptions(), ManualClock()).name == "fake"
