"""`open_tracker(url)`: a host client of the native protocol over any link (docs/protocol.md).

    with open_tracker("socket://127.0.0.1:5555") as tracker:     # handshake: GET_INFO, version check
        tracker.configure(rate_hz=500)
        tracker.start()
        for sample in tracker.samples(count=1000):                # eyehil.drivers.wire.Sample
            ...
        tracker.stop()
        print(tracker.stats)                                      # lost frames, CRC errors, retries ...

Commands follow the protocol's rules: one outstanding at a time; a response missing after
`response_timeout` (0.25 s) counts as lost and the command is re-sent with a new sequence number,
`retries` times, then `TrackerTimeoutError`; a late response to an earlier attempt is accepted. A START
whose ACK was lost and that gets BUSY on the retry was accepted. ERROR raises `CommandRefusedError`.
Every wait has a deadline on ``time.monotonic()``: nothing blocks forever.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from eyehil.drivers.errors import CommandRefusedError, IncompatibleDeviceError, TrackerError, TrackerTimeoutError
from eyehil.drivers.links import open_link
from eyehil.drivers.wire import Reply, Sample, Wire
from eyehil.protocols.enums import Capability, DeviceState, EyeSelect, StimulusFlags, StreamSelect
from eyehil.protocols.errors import ErrorCode
from eyehil.protocols.header import PROTOCOL_VERSION
from eyehil.protocols.messages import Configure, GetInfo, GetStatus, Ping, Start, Stimulus, Stop
from eyehil.protocols.native import Message
from eyehil.protocols.replies import Ack, DeviceInfo, ErrorReply, Pong, Status


@dataclass(frozen=True)
class ClockSync:
    """Device clock minus host clock (us) from the PING with the smallest round trip (us)."""

    offset_us: float
    rtt_us: float

    def to_host_us(self, device_us: float) -> float:
        """A device timestamp on the host's clock."""
        return device_us - self.offset_us


def _matches(message: Message, seqs: set[int]) -> Callable[[Reply], bool]:
    """Which reply answers `message`, sent (possibly several times) with the sequence numbers `seqs`."""
    def match(reply: Reply) -> bool:
        m = reply.message
        if isinstance(m, Ack):
            return m.acked_seq in seqs
        if isinstance(m, ErrorReply):
            return m.offending_seq in seqs
        if isinstance(m, Pong):
            return isinstance(message, Ping) and m.nonce == message.nonce
        return (isinstance(m, DeviceInfo) and isinstance(message, GetInfo)) or (
            isinstance(m, Status) and isinstance(message, GetStatus))
    return match


class Tracker:
    """A connected tracker; see the module docstring. `info` is its DEVICE_INFO after the handshake."""

    def __init__(self, link, *, timeout: float = 2.0, response_timeout: float = 0.25, retries: int = 3,
                 handshake: bool = True, url: str = "") -> None:
        """Talk over `link` (SerialLike); `timeout` bounds every wait for samples (s)."""
        self.wire, self.url = Wire(link), url
        self.timeout, self.response_timeout, self.retries = timeout, response_timeout, retries
        self.info: DeviceInfo | None = None
        self.configuration: Configure | None = None  # the last CONFIGURE the device accepted from this client
        self.streaming = False
        if handshake:
            self.handshake()

    @property
    def stats(self):
        """`eyehil.drivers.wire.HostStats` of this link."""
        return self.wire.stats

    def handshake(self) -> DeviceInfo:
        """Terminate the device's partial input, drop stale input, GET_INFO, check the protocol version."""
        self.wire.write(b"\x00")
        if hasattr(self.wire.link, "reset_input_buffer"):
            self.wire.link.reset_input_buffer()
        info = self.command(GetInfo())
        if not info.protocol_min <= PROTOCOL_VERSION <= info.protocol_max:
            raise IncompatibleDeviceError(f"device speaks versions {info.protocol_min}..{info.protocol_max}, "
                                     f"host speaks {PROTOCOL_VERSION}")
        self.info = info
        self.streaming = self.status().state is DeviceState.STREAMING
        return info

    # --- commands -----------------------------------------------------------------------------
    def command(self, message: Message) -> Message:
        """Send `message`, return its response (re-sending on a missing response); ERROR raises."""
        return self.exchange(message).message

    def exchange(self, message: Message) -> Reply:
        """Like `command`, but return the whole `Reply` (header, arrival time).

        A response to an earlier attempt of the same command that arrives late is accepted too.
        """
        seqs: set[int] = set()
        for attempt in range(self.retries + 1):
            seqs.add(self.wire.send(message)[0])
            reply = self._await(_matches(message, seqs))
            if reply is None:
                self.wire.stats.retries += 1
                continue
            m = reply.message
            if isinstance(m, ErrorReply):
                if attempt > 0 and isinstance(message, Start) and m.code == ErrorCode.BUSY:
                    return reply  # our first START was accepted, its ACK lost
                raise CommandRefusedError(type(message).__name__.upper(), int(m.code), m.text)
            return reply
        raise TrackerTimeoutError(f"no response to {type(message).__name__} after {self.retries + 1} attempts")

    def _await(self, match: Callable[[Reply], bool]) -> Reply | None:
        """The first reply satisfying `match` within `response_timeout`; None if none came (others are
        dropped as stale)."""
        deadline = time.monotonic() + self.response_timeout
        while True:
            while self.wire.replies:
                reply = self.wire.replies.popleft()
                if match(reply):
                    return reply
                self.wire.stats.stale_replies += 1
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self.wire.pump(remaining)

    def status(self) -> Status:
        return self.command(GetStatus())

    def sync_clock(self, pings: int = 8) -> ClockSync:
        """Device minus host clock from `pings` PINGs, keeping the smallest round trip (docs/protocol.md, PONG)."""
        best: ClockSync | None = None
        for nonce in range(pings):
            reply = self.exchange(Ping(nonce))
            pong: Pong = reply.message
            t1, t2 = pong.ping_timestamp_us, pong.receive_time_us
            t3, t4 = reply.received.header.timestamp_us, reply.host_us
            sync = ClockSync(((t2 - t1) + (t3 - t4)) / 2, (t4 - t1) - (t3 - t2))
            best = sync if best is None or sync.rtt_us < best.rtt_us else best
        return best

    def configure(self, *, leds: int | None = None, rate_hz: int | None = None, eyes: EyeSelect | None = None,
                  stream: StreamSelect = StreamSelect.FEATURES, roi: tuple[int, int, int, int] = (0, 0, 0, 0)
                  ) -> Configure:
        """CONFIGURE; unspecified fields: all LEDs, the device's current rate, both eyes if binocular."""
        info = self._info()
        binocular = Capability.BINOCULAR in info.capabilities
        cfg = Configure(leds or info.led_count, rate_hz or info.sample_rate_hz,
                        eyes or (EyeSelect.BOTH if binocular else EyeSelect.RIGHT), stream, *roi)
        self.command(cfg)
        self.configuration = cfg
        self.info = self.command(GetInfo())
        return cfg

    def start(self) -> None:
        """START streaming (the next samples belong to a new stream)."""
        self.wire.new_stream()
        self.command(Start())
        self.streaming = True

    def stop(self) -> None:
        """STOP; samples queued before its ACK stay readable."""
        self.command(Stop())
        self.streaming = False

    def stimulus(self, target_id: int, x_mm: float, y_mm: float, visible: bool = True) -> int:
        """Show a target to the simulated subject (emulator only); return the device time of the ACK (us).

        Coordinates: mm from the screen's top-left corner, x right, y down, as the subject sees it.
        """
        if Capability.STIMULUS not in self._info().capabilities:
            raise IncompatibleDeviceError("this device has no simulated subject (no STIMULUS capability)")
        flags = StimulusFlags.VISIBLE if visible else StimulusFlags(0)
        return self.exchange(Stimulus(target_id, x_mm, y_mm, flags)).received.header.timestamp_us

    def _info(self) -> DeviceInfo:
        if self.info is None:
            raise TrackerError("no handshake yet")
        return self.info

    # --- samples ------------------------------------------------------------------------------
    def read_sample(self, timeout: float | None = None) -> Sample:
        """The next sample; `TrackerTimeoutError` if none arrives within `timeout` (default `self.timeout`) s."""
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while not self.wire.samples:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TrackerTimeoutError(f"no sample within {self.timeout if timeout is None else timeout} s")
            self.wire.pump(remaining)
        return self.wire.samples.popleft()

    def samples(self, count: int | None = None, timeout: float | None = None) -> Iterator[Sample]:
        """Iterate over samples (`count` of them, or until the caller stops); each waits at most `timeout` s."""
        n = 0
        while count is None or n < count:
            yield self.read_sample(timeout)
            n += 1

    def drain(self) -> list[Sample]:
        """Every sample received so far (reads what is already waiting on the link, without blocking)."""
        while self.wire.pump(0):
            pass
        out = list(self.wire.samples)
        self.wire.samples.clear()
        return out

    # --- lifetime -----------------------------------------------------------------------------
    def close(self, stop: bool = True) -> None:
        """Close the link; first STOP a stream this client started (best effort) unless `stop` is False."""
        try:
            if stop and self.streaming:
                self.response_timeout, self.retries = min(self.response_timeout, 0.25), 0
                self.stop()
        except TrackerError:
            pass
        finally:
            self.wire.close()

    def __enter__(self) -> Tracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_tracker(url: str, **kwargs) -> Tracker:
    """Open `url` (see `eyehil.drivers.links.SCHEMES`) and handshake; keyword arguments go to `Tracker`."""
    link = open_link(url, timeout=0.0)
    try:
        return Tracker(link, url=url, **kwargs)
    except BaseException:
        link.close()
        raise
