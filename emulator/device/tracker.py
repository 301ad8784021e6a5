"""`VirtualTracker`: the device side of the native protocol (docs/protocol.md), free of any transport.

Bytes in, bytes out (the style of pyvisa-sim's devices): a link hands received bytes to `feed`, calls
`poll` when samples may be due, and writes whatever `read_available` returns. Nothing here blocks,
sleeps or starts a thread; the core is not thread-safe (a link runner serialises the calls).

- State machine: IDLE / STREAMING; one configuration (defaults until CONFIGURE), applied at START.
- Every command gets exactly one response, in order (PONG, DEVICE_INFO, STATUS, ACK or ERROR); frames
  failing the framing, CRC or magic checks get none and are only counted (`eyehil.protocols.stream`).
- Streaming: one FEATURES per exposure at the configured rate, timestamped at mid-exposure; samples
  that would push the output backlog past `max_output_bytes` are dropped (STATUS `samples_dropped`,
  gaps in `frame_id`), never queued without bound.
- Frames (if the subject's solver carries appearance channels): each exposure's images as FRAME_CHUNKs
  behind the FEATURES (`frame_stream`; dropped images counted in `frames_dropped`). The FEATURES limit
  grows by the frame budget, which the link's backlog may hold in chunks. With frames, `next_due_us` asks
  for one exposure at a time (a fast clock never outruns the images) and for an early look while images
  render or chunks wait; `fast_room` tells a fast clock's runner when the next exposure may start.
- A new connection (`connection_reset`) starts a fresh session: IDLE, default configuration, nothing queued.
- STIMULUS moves the simulated subject's target (`eyehil.emulator.device.stimulus`); it never waits for the
  subject's fixation solve (`eyehil.emulator.device.subject`), so its ACK is immediate.
- Replies are bounded too: a reply that would push the output past `max_output_bytes` + `REPLY_HEADROOM`
  (a host that sends commands and never reads) is dropped and counted (`replies_dropped`).
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.device.camera import FAST_PREPARE_MIN, FAST_PREPARE_S, Camera, Selection
from eyehil.emulator.device.clock import Clock, RealTimeClock
from eyehil.emulator.device.frame_stream import FrameOptions, FrameStream
from eyehil.emulator.device.links.base import FAST_LOW_WATER, take
from eyehil.emulator.device.stimulus import stimulus_problem, stimulus_to_screen
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.batch import pack_features_batch
from eyehil.protocols.enums import Capability, DeviceState, Eye, EyeSelect, StimulusFlags, StreamSelect
from eyehil.protocols.errors import ErrorCode
from eyehil.protocols.framing import encode_frame
from eyehil.protocols.header import MAX_PAYLOAD, PROTOCOL_VERSION, Header
from eyehil.protocols.messages import Configure, GetInfo, GetStatus, Ping, Start, Stimulus, Stop
from eyehil.protocols.native import (
    HOST_TYPES,
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    Message,
    check_configure,
    default_configure,
    encode,
)
from eyehil.protocols.replies import Ack, DeviceInfo, ErrorReply, Pong, Status
from eyehil.protocols.samples import EYE_RECORD, FEATURES_HEAD, GLINT_RECORD
from eyehil.protocols.stream import NativeReceiver, Received, SequenceTracker

MODEL = "eyehil virtual tracker"
FIRMWARE_VERSION = "0.1.0"
U32 = 1 << 32
PENDING_WAKE_US = 500  # while chunks wait, the runner looks again this soon (device us)
REPLY_HEADROOM = 64 * 1024  # bytes of replies the output may hold beyond the sample limit


class VirtualTracker:
    """The emulated eye tracker speaking the native protocol; see the module docstring."""

    def __init__(self, subject: Subject, clock: Clock | None = None, *, default_rate_hz: int = 250,
                 max_output_bytes: int = 32_768, frames: FrameOptions | None = None) -> None:
        """A device in front of `subject` (its scene gives the sensor, the LEDs and the eyes it can see); it streams
        frames (as `frames` say) if the subject's solver carries appearance channels."""
        scene = subject.solver.scene
        if len(scene.leds) not in (1, 2):
            raise ValueError(f"the protocol supports 1 or 2 LEDs; scene {scene.name} has {len(scene.leds)}")
        if not MIN_RATE_HZ <= default_rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"default rate {default_rate_hz} Hz outside {MIN_RATE_HZ}..{MAX_RATE_HZ}")
        self.subject, self.clock = subject, clock or RealTimeClock()
        if hasattr(self.clock, "paused"):
            subject.pause_clock = self.clock.paused  # a fast clock's virtual time waits for the subject's solves
        self.sensor = tuple(int(v) for v in scene.camera.resolution_px)
        self.tracked = tuple(Eye.RIGHT if s == "right" else Eye.LEFT for s in scene.sides)
        self.camera = Camera(subject, self.sensor, self.tracked)
        if self.clock.fast:
            self.camera.prepare_s, self.camera.prepare_min = FAST_PREPARE_S, FAST_PREPARE_MIN
        self.frames = FrameStream.for_subject(subject, self.tracked, frames)  # None: this subject has no images
        self._stream = StreamSelect.FEATURES
        self.max_output_bytes = max_output_bytes
        self.state = DeviceState.IDLE
        self._rate = default_rate_hz
        self._config: Configure | None = None
        self._rx = NativeReceiver(accept=HOST_TYPES)
        self._out = bytearray()
        self._seq = 0
        self._tx = {"tx_frames": 0, "samples_sent": 0, "samples_dropped": 0, "commands_refused": 0}
        self.replies_dropped = 0
        self._sample_size = 0
        self._handlers = {Ping: self._ping, GetInfo: self._info, GetStatus: self._status, Configure: self._configure,
                          Start: self._start, Stop: self._stop, Stimulus: self._stimulus}

    # --- identity and counters ------------------------------------------------------------
    @property
    def info(self) -> DeviceInfo:
        """DEVICE_INFO as the device would send it now (the rate reflects an accepted CONFIGURE)."""
        caps = Capability.FEATURES | Capability.ROI | Capability.TIME_SYNC | Capability.STIMULUS | Capability.ISCAN
        caps |= Capability.BINOCULAR if len(self.tracked) == 2 else 0
        caps |= Capability.FRAMES if self.frames is not None else 0
        rate = self._config.rate_hz if self._config else self._rate
        return DeviceInfo(PROTOCOL_VERSION, PROTOCOL_VERSION, *self.sensor, MIN_RATE_HZ, MAX_RATE_HZ, rate,
                          len(self.subject.solver.scene.leds), caps, MAX_PAYLOAD, MODEL, FIRMWARE_VERSION)

    def status(self) -> Status:
        """STATUS counters (wrapping at 2^32)."""
        c = self._rx.counters
        rx = {name: getattr(c, name) % U32 for name in ("rx_frames", "crc_errors", "framing_errors",
                                                          "oversized_frames", "unknown_messages", "version_errors",
                                                          "malformed_messages")}
        tx = {name: value % U32 for name, value in self._tx.items()}
        sent, dropped = (self.frames.sent, self.frames.dropped) if self.frames else (0, 0)
        return Status(self.state, frames_sent=sent % U32, frames_dropped=dropped % U32, **rx, **tx)

    # --- bytes in ---------------------------------------------------------------------------
    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Consume bytes from the host; queue the responses. Never raises on bad input."""
        for event in self._rx.feed(data):
            if isinstance(event, Received):
                self._respond(self._handlers[type(event.message)](event.header, event.message))
            elif event.reply is not None:
                self._respond(event.reply)

    def connection_reset(self) -> None:
        """A new host connected (a new byte stream): the session is fresh. Forget a partial frame, the host's
        sequence baseline and every response or sample queued for the previous host; stop a stream it left
        running (images abandoned are counted in `frames_dropped`) and go back to the default configuration."""
        self._rx.framer.reset()
        self._rx.sequence = SequenceTracker()
        if self.state is DeviceState.STREAMING:
            self.camera.stop()
            if self._with_frames:
                self.frames.stop()
            self.state = DeviceState.IDLE
        self._config = None
        self._out.clear()

    def _respond(self, message: Message) -> None:
        """Queue one response with the next sequence number, stamped now (dropped, counted, beyond the limit)."""
        budget = self.frames.options.budget_bytes if self.frames is not None else 0
        if len(self._out) >= self.max_output_bytes + budget + REPLY_HEADROOM:
            self.replies_dropped += 1
            return
        self._out += encode(message, self._seq, self.clock.now_us())
        self._seq = (self._seq + 1) % U32
        self._tx["tx_frames"] += 1
        self._tx["commands_refused"] += isinstance(message, ErrorReply)

    # --- command handlers: (header, message) -> the one response ------------------------------
    @staticmethod
    def _ack(h: Header) -> Ack:
        return Ack(h.seq, h.msg_type)

    @staticmethod
    def _error(h: Header, code: ErrorCode, text: str) -> ErrorReply:
        return ErrorReply(code, h.seq, h.msg_type, text)

    def _ping(self, h: Header, m: Ping) -> Pong:
        return Pong(m.nonce, h.timestamp_us, self.clock.now_us())

    def _info(self, h: Header, m: GetInfo) -> DeviceInfo:
        return self.info

    def _status(self, h: Header, m: GetStatus) -> Status:
        return self.status()

    def _configure(self, h: Header, m: Configure) -> Ack | ErrorReply:
        if self.state is DeviceState.STREAMING:
            return self._error(h, ErrorCode.BUSY, "CONFIGURE while streaming")
        refusal = check_configure(m, self.info)
        if refusal is not None:
            return self._error(h, *refusal)
        self._config = m
        return self._ack(h)

    def _start(self, h: Header, m: Start) -> Ack | ErrorReply:
        if self.state is DeviceState.STREAMING:
            return self._error(h, ErrorCode.BUSY, "already streaming")
        cfg = self._config or default_configure(self.info)
        eyes = tuple(e for e in (Eye.RIGHT, Eye.LEFT) if EyeSelect(1 << e) in cfg.eyes)
        roi = (cfg.roi_x, cfg.roi_y, cfg.roi_w, cfg.roi_h) if cfg.roi_w else None
        selection = Selection(eyes, cfg.leds, roi)
        self.camera.start(self.clock.now_us(), cfg.rate_hz, selection)
        self._stream = cfg.stream
        if self._with_frames:
            self.frames.start(selection)
        self._sample_size = FEATURES_HEAD.size + len(eyes) * (EYE_RECORD.size + cfg.leds * GLINT_RECORD.size) + 22
        self.state = DeviceState.STREAMING
        return self._ack(h)

    def _stop(self, h: Header, m: Stop) -> Ack:
        if self.state is DeviceState.STREAMING:
            self.camera.stop()
            if self._with_frames:
                self.frames.stop()
            self.state = DeviceState.IDLE
        return self._ack(h)

    def _stimulus(self, h: Header, m: Stimulus) -> Ack | ErrorReply:
        screen = self.subject.solver.scene.screen
        problem = stimulus_problem(screen, m.x_mm, m.y_mm)
        if problem is not None:
            return self._error(h, ErrorCode.INVALID_ARGUMENT, problem)
        if StimulusFlags.VISIBLE in m.flags:
            effect_us = self.subject.look_at(stimulus_to_screen(screen, m.x_mm, m.y_mm), self.clock.now_us())
            self.camera.invalidate(effect_us)
        return self._ack(h)

    # --- bytes out --------------------------------------------------------------------------
    @property
    def _with_frames(self) -> bool:
        return self.frames is not None and StreamSelect.FRAMES in self._stream

    def next_due_us(self, count: int = 1, wake: bool = True) -> int | None:
        """Device time by which the next `count` samples are due (one with frames; with `wake`, sooner while images
        render or chunks wait), or None when idle."""
        if self.state is not DeviceState.STREAMING:
            return None
        count = 1 if self._with_frames else count
        due = self.camera.time_of(self.camera.taken + count - 1)
        early = wake and self._with_frames and self.frames.pending
        return min(due, self.clock.now_us() + PENDING_WAKE_US) if early else due

    def fast_room(self, backlog: int) -> bool:
        """Fast clock: may the runner take the next exposure now, with `backlog` bytes in the link? FEATURES only:
        while the link holds less than `FAST_LOW_WATER`. With frames: while an exposure may start rendering
        (`frame_stream.FrameStream.room`) and the link holds less than the frame budget, so the next image renders
        while the link carries the previous ones; both bounds are fixed, so the backlog stays bounded."""
        if self.state is not DeviceState.STREAMING or not self._with_frames:
            return backlog < FAST_LOW_WATER
        return self.frames.room > 0 and backlog < self.frames.options.budget_bytes

    def set_wake(self, wake) -> None:
        """`wake()` is called (from another thread) when an image finishes rendering: the runner looks again."""
        if self.frames is not None:
            self.frames.on_done = wake

    def poll(self, now_us: int | None = None, backlog: int = 0) -> int:
        """Queue the samples due by `now_us` (default: the clock); return how many exposures were taken.

        `backlog`: bytes already queued downstream (in the link). FEATURES that do not fit under
        `max_output_bytes` (plus the frame budget when frames are streamed) are dropped, the oldest first, and
        counted in `samples_dropped`; images as `frame_stream` says.
        """
        if self.state is not DeviceState.STREAMING:
            return 0
        if self._with_frames:
            self.frames.downstream(backlog)
        due = self.camera.due(self.clock.now_us() if now_us is None else now_us)
        if due == 0:
            return 0
        room = self._room(backlog) if StreamSelect.FEATURES in self._stream else due
        if room < due:
            self.camera.skip(due - room)
            self._tx["samples_dropped"] += due - room
            if self._with_frames:
                self.frames.skip(due - room)
        if room == 0:
            return 0
        exp = self.camera.take(min(room, due))
        if StreamSelect.FEATURES in self._stream:
            self._queue_features(exp)
        if self._with_frames:
            self.frames.offer(exp)
        return len(exp)

    def _room(self, backlog: int) -> int:
        """How many FEATURES fit in the output limit now."""
        limit = self.max_output_bytes + (self.frames.options.budget_bytes if self._with_frames else 0)
        return max(0, limit - len(self._out) - backlog) // self._sample_size

    def _queue_features(self, exp) -> None:
        """Encode the FEATURES of exposures `exp` (camera.Exposures) into the output."""
        frames = pack_features_batch(exp.batch, self._seq, exp.time_us)
        rows = frames.view(np.uint8).reshape(len(frames), -1)
        self._out += b"".join(encode_frame(row.tobytes()) for row in rows)
        self._seq = (self._seq + len(exp)) % U32
        self._tx["tx_frames"] += len(exp)
        self._tx["samples_sent"] += len(exp)

    @property
    def pending(self) -> int:
        """Bytes queued for the host."""
        return len(self._out)

    def read_available(self, max_bytes: int | None = None) -> bytes:
        """Take up to `max_bytes` (default all) queued bytes for the host; chunks join as the frame budget allows."""
        if self._with_frames and self.frames.pending and self.state is DeviceState.STREAMING:
            data, n = self.frames.release(len(self._out), self._seq)
            self._seq = (self._seq + n) % U32
            self._tx["tx_frames"] += n
            if not self._out and (max_bytes is None or len(data) <= max_bytes):
                return data  # only chunks wait: handed over as they are, not copied through the queue
            self._out += data
        return take(self._out, max_bytes)

    def close(self) -> None:
        """Release the subject's worker thread and the render workers."""
        if self.frames is not None:
            self.frames.close()
        self.subject.close()
