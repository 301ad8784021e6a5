"""A fault-injecting SerialLike wrapper: drop, duplicate, corrupt, delay, reorder frames, and disconnect.

    link = FaultLink(open_link(url, timeout=0.0), FaultSpec.parse("drop=0.01,corrupt=0.001,delay=5ms"))
    tracker = Tracker(link)                                  # or: eyehil stream URL --fault drop=0.01,...

Faults apply to the device -> host direction, frame by frame (a frame is everything up to and including a
0x00 delimiter), each frame independently with the given probabilities, from a seeded generator:

- ``drop=P``: the frame is not delivered;
- ``duplicate=P``: the frame is delivered twice;
- ``corrupt=P``: one bit of the decoded frame is flipped and the frame re-encoded: exactly one bit error,
  which the CRC-16 always detects (a damaged frame can never pass as a good one);
- ``delay=T`` with ``delay_p=P`` (default 0.005 when a delay is given): the frame is held back for T
  (``5ms``, ``0.2s``) on the wrapper's clock and delivered after the frames that came meanwhile;
- ``reorder=P``: the frame is swapped with the next one;
- ``disconnect=N``: after N frames the link fails (``read``/``write`` raise `ConnectionResetError`) for
  ``outage=M`` frames (default 100) that the device sends meanwhile (all lost), then works again.
- ``after=N``: the first N frames pass untouched (a clean handshake);
- ``seed=S``: the generator's seed (default 0).

`log` records what happened to which frame (a diagnostic tool: its lists grow with the run), by the
frame's sequence number (`FaultLog`; None for a frame too damaged to tell): tests compare the host's
counters with it. The wrapper's clock (`now`, seconds) is injectable, so a test runs on simulated time.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from eyehil.protocols import cobs

KINDS = ("drop", "duplicate", "corrupt", "delay", "reorder")


@dataclass(frozen=True)
class FaultSpec:
    """Fault probabilities (per frame), the delay (s), the disconnect point and outage (frames), the seed."""

    drop: float = 0.0
    duplicate: float = 0.0
    corrupt: float = 0.0
    reorder: float = 0.0
    delay_p: float = 0.0
    delay_s: float = 0.0
    after: int = 0  # frames passed untouched first (a clean handshake)
    disconnect: int = 0  # frames before the link fails once (0: never)
    outage: int = 100  # frames lost while it is down
    seed: int = 0

    @classmethod
    def parse(cls, text: str) -> FaultSpec:
        """``drop=0.01,duplicate=0.005,corrupt=0.001,delay=5ms,delay_p=0.01,reorder=0.005,disconnect=5000``."""
        values: dict[str, float | int] = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, value = item.partition("=")
            if not sep:
                raise ValueError(f"fault {item!r}: expected key=value")
            if key == "delay":
                values["delay_s"] = _seconds(value)
                values.setdefault("delay_p", 0.005)
            elif key in ("after", "disconnect", "outage", "seed"):
                values[key] = int(value)
            elif key in ("drop", "duplicate", "corrupt", "reorder", "delay_p"):
                p = float(value)
                if not 0.0 <= p <= 1.0:
                    raise ValueError(f"fault {key}: probability {p} not in 0..1")
                values[key] = p
            else:
                raise ValueError(f"unknown fault {key!r}; known: {', '.join(KINDS)}, delay_p, disconnect, outage, seed")
        return cls(**values)


def _seconds(text: str) -> float:
    """``5ms``, ``0.2s``, ``200us`` or a plain number of seconds."""
    for suffix, scale in (("ms", 1e-3), ("us", 1e-6), ("s", 1.0)):
        if text.endswith(suffix):
            return float(text[: -len(suffix)]) * scale
    return float(text)


@dataclass
class FaultLog:
    """What the wrapper did, by the frames' sequence numbers."""

    frames: int = 0  # device frames seen (empty ones, lone delimiters, not counted)
    dropped: list[int | None] = field(default_factory=list)
    duplicated: list[int | None] = field(default_factory=list)
    corrupted: list[int | None] = field(default_factory=list)
    delayed: list[int | None] = field(default_factory=list)
    reordered: list[int | None] = field(default_factory=list)
    outage: list[int | None] = field(default_factory=list)  # frames lost while disconnected
    disconnects: int = 0
    in_order: list[int] = field(default_factory=list)  # seqs delivered intact after every lower one delivered
    last_in_order: int | None = None  # the highest seq delivered intact
    bytes_read: int = 0  # bytes the host has read from the wrapper
    damaged_ends: list[int] = field(default_factory=list)  # stream offsets where each damaged copy ends

    @property
    def damaged_read(self) -> int:
        """Damaged frame copies the host has read in full (a corrupted frame delivered twice counts twice)."""
        return sum(1 for end in self.damaged_ends if end <= self.bytes_read)


class FaultLink:
    """A SerialLike around `inner` that injects `spec`'s faults into what it reads; see the module docstring."""

    def __init__(self, inner, spec: FaultSpec, now: Callable[[], float] = time.monotonic) -> None:
        self.inner, self.spec, self.now = inner, spec, now
        self.rng = random.Random(spec.seed)
        self.log = FaultLog()
        self._partial = bytearray()
        self._ready = bytearray()
        self._held: list[tuple[float, int | None, bytes, bool]] = []  # (due time, seq, frame, damaged) delayed
        self._swap: tuple[bytes, int | None, bool] | None = None  # a frame to deliver after the next one
        self._queued = 0  # bytes ever put in `_ready`
        self._down = 0  # frames still to lose in the current outage
        self._failed = False  # the next read/write raises once

    # --- SerialLike -------------------------------------------------------------------------------------------
    @property
    def timeout(self):
        return self.inner.timeout

    @timeout.setter
    def timeout(self, value) -> None:
        self.inner.timeout = value

    def read(self, size: int = 1) -> bytes:
        self._raise_if_failed()
        self._partial += self.inner.read(max(size, 4096))
        while (end := self._partial.find(0)) >= 0:
            frame = bytes(self._partial[: end + 1])
            del self._partial[: end + 1]
            self._frame(frame)
        self._release_held()
        self._raise_if_failed()
        data = bytes(self._ready[:size])
        del self._ready[:size]
        self.log.bytes_read += len(data)
        return data

    def write(self, data: bytes) -> int | None:
        self._raise_if_failed()
        return self.inner.write(data)

    def reset_input_buffer(self) -> None:
        if hasattr(self.inner, "reset_input_buffer"):
            self.inner.reset_input_buffer()

    def close(self) -> None:
        self.inner.close()

    # --- faults ------------------------------------------------------------------------------------------------
    def _raise_if_failed(self) -> None:
        if self._failed:
            self._failed = False
            raise ConnectionResetError("fault injection: the link failed")

    def _frame(self, frame: bytes) -> None:
        if frame == b"\x00":  # an empty frame (a lone delimiter) carries nothing: pass it on
            self._deliver(frame, None)
            return
        spec, log = self.spec, self.log
        log.frames += 1
        index = _seq_of(frame)
        if spec.disconnect and log.frames == spec.disconnect:
            self._down, self._failed = spec.outage, True
            log.disconnects += 1
        if self._down > 0:
            self._down -= 1
            log.outage.append(index)
            return
        if log.frames <= spec.after:
            self._deliver(frame, index)
            return
        r = self.rng.random
        if r() < spec.drop:
            log.dropped.append(index)
            return
        damaged = False
        if r() < spec.corrupt:
            log.corrupted.append(index)
            frame, damaged = _flip_one_bit(frame, self.rng), True
        seq = None if damaged else index
        if r() < spec.delay_p and spec.delay_s > 0:
            log.delayed.append(index)
            self._held.append((self.now() + spec.delay_s, seq, frame, damaged))
            return
        copies = 2 if r() < spec.duplicate else 1
        if copies == 2:
            log.duplicated.append(index)
        if self._swap is None and r() < spec.reorder:
            log.reordered.append(index)
            self._swap = (frame * copies, seq, damaged)
            return
        self._deliver(frame * copies, seq, damaged)
        if self._swap is not None:
            self._deliver(*self._swap)
            self._swap = None

    def _release_held(self) -> None:
        now = self.now()
        due = [h for h in self._held if h[0] <= now]
        if due:
            self._held = [h for h in self._held if h[0] > now]
            for _, seq, frame, damaged in due:
                self._deliver(frame, seq, damaged)

    def _deliver(self, frames: bytes, seq: int | None, damaged: bool = False) -> None:
        """Hand `frames` (one frame, or the same frame twice) to the host; `seq` None if damaged or unknown."""
        if damaged:  # where each copy ends in the stream the host reads
            size = len(frames) // frames.count(0)
            self.log.damaged_ends += [self._queued + size * (k + 1) for k in range(frames.count(0))]
        self._queued += len(frames)
        self._ready += frames
        last = self.log.last_in_order
        if seq is not None and (last is None or seq > last):
            self.log.in_order.append(seq)
            self.log.last_in_order = seq


def _seq_of(wire: bytes) -> int | None:
    """The header sequence number of one COBS frame, or None if it cannot be read."""
    try:
        raw = cobs.decode(wire[:-1])
    except ValueError:
        return None
    return int.from_bytes(raw[4:8], "little") if len(raw) >= 8 else None


def _flip_one_bit(wire: bytes, rng: random.Random) -> bytes:
    """`wire` (one COBS frame and its delimiter) with one bit of the decoded frame flipped, re-encoded."""
    try:
        raw = bytearray(cobs.decode(wire[:-1]))
    except ValueError:
        return wire
    if not raw:
        return wire
    bit = rng.randrange(8 * len(raw))
    raw[bit // 8] ^= 1 << (bit % 8)
    return cobs.encode(bytes(raw)) + b"\x00"


def wrap(link, spec_text: str | None, now: Callable[[], float] = time.monotonic):
    """`link` wrapped in a `FaultLink` if `spec_text` is given (the CLI's ``--fault``), else `link` itself."""
    return FaultLink(link, FaultSpec.parse(spec_text), now) if spec_text else link
