"""`IscanTracker`: the same virtual device speaking the ISCAN-compatible legacy mode (docs/protocol.md §13).

Same interface as `VirtualTracker` (feed / poll / read_available / next_due_us / connection_reset /
close), so every link carries either. The host sends single bytes: 0x80 starts streaming, 0x81 stops,
anything else is ignored. While started, one record per exposure: the header word 0x4444 and the
configured outputs (default pupil H, pupil V, corneal reflection H, V) as round(px x 10); the
corneal reflection is the glint of LED 0 of the first eye the scene tracks (right if both); a value
not found is sent as 0. The rate is fixed out of band (the `--rate` of `eyehil emulate`); there are
no sequence numbers, replies or counters on the wire (`status` reports them locally).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from eyehil.emulator.device.camera import Camera, Selection
from eyehil.emulator.device.clock import Clock, RealTimeClock
from eyehil.emulator.device.links.base import take
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.enums import Eye, GlintFlags, PupilFlags
from eyehil.protocols.iscan import (
    DEFAULT_OUTPUTS,
    IscanCommand,
    IscanOutput,
    encode_samples,
    parse_commands,
    select_outputs,
)


class IscanTracker:
    """The emulated tracker in ISCAN mode; see the module docstring."""

    def __init__(self, subject: Subject, clock: Clock | None = None, *, rate_hz: int = 120,
                 outputs: Sequence[IscanOutput] = DEFAULT_OUTPUTS, max_output_bytes: int = 16_384) -> None:
        """Stream `outputs` of the first tracked eye at `rate_hz` while started."""
        scene = subject.solver.scene
        self.subject, self.clock = subject, clock or RealTimeClock()
        self.rate_hz, self.outputs, self.max_output_bytes = rate_hz, tuple(outputs), max_output_bytes
        tracked = tuple(Eye.RIGHT if s == "right" else Eye.LEFT for s in scene.sides)
        self.camera = Camera(subject, tuple(int(v) for v in scene.camera.resolution_px), tracked)
        self._selection = Selection(tracked[:1], 1)
        self.streaming = False
        self.counters = {"samples_sent": 0, "samples_dropped": 0, "commands": 0, "bytes_ignored": 0}
        self._record = 2 * (len(self.outputs) + 1)
        self._out = bytearray()

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Handle START / STOP bytes; ignore the rest."""
        commands = parse_commands(data)
        self.counters["commands"] += len(commands)
        self.counters["bytes_ignored"] += len(bytes(data)) - len(commands)
        for command in commands:
            if command is IscanCommand.START and not self.streaming:
                self.camera.start(self.clock.now_us(), self.rate_hz, self._selection)
                self.streaming = True
            elif command is IscanCommand.STOP and self.streaming:
                self.camera.stop()
                self.streaming = False

    def connection_reset(self) -> None:
        """Nothing to forget: ISCAN commands are single bytes."""

    def next_due_us(self, count: int = 1, wake: bool = True) -> int | None:
        """Device time by which the next `count` records are due, or None when stopped (`wake`: no early look)."""
        return self.camera.time_of(self.camera.taken + count - 1) if self.streaming else None

    def poll(self, now_us: int | None = None, backlog: int = 0) -> int:
        """Queue the records due by `now_us`; drop (and count) those that do not fit; return how many were queued."""
        if not self.streaming:
            return 0
        due = self.camera.due(self.clock.now_us() if now_us is None else now_us)
        room = max(0, self.max_output_bytes - len(self._out) - backlog) // self._record
        if room < due:
            self.camera.skip(due - room)
            self.counters["samples_dropped"] += due - room
        count = min(room, due)
        if count == 0:
            return 0
        b = self.camera.take(count).batch
        pupil = np.where((b.flags[:, 0] & PupilFlags.DETECTED)[:, None] > 0, b.centre[:, 0], np.nan)
        cr = np.where((b.glint_flags[:, 0, 0] & GlintFlags.VALID)[:, None] > 0, b.glint_xy[:, 0, 0], np.nan)
        self._out += encode_samples(select_outputs(pupil, cr, self.outputs))
        self.counters["samples_sent"] += count
        return count

    @property
    def pending(self) -> int:
        """Bytes queued for the host."""
        return len(self._out)

    def read_available(self, max_bytes: int | None = None) -> bytes:
        """Take up to `max_bytes` (default all) queued bytes."""
        return take(self._out, max_bytes)

    def close(self) -> None:
        """Release the subject's worker thread."""
        self.subject.close()
