"""The facade's side of the LSL outlet: `GazeOutlet` maps blocks to samples and LSL times and hands them to the
outlet process (`process`), which owns liblsl.

One sample per exposure (nominal rate: the exposure rate), ``cf_double64``, NaN where a value is unknown; the
channels are those of `channels` (eyehil's, or Pupil Capture's LSL relay with name ``pupil_capture``).

The source id is stable across restarts of the same device (`stable_source_id`: a hash of what defines the
device), so that a recorder (LabRecorder) finds the stream again after a restart.

Network exposure (`bind`): "loopback" (the default, as every eyehil server) keeps the outlet on this machine:
discovery on 127.0.0.1 (`library.LOOPBACK_CONFIG`) and, through the loopback bind library preloaded into the
outlet process (`loopback`), liblsl's data (TCP) and time (UDP) ports on 127.0.0.1 too. "all" leaves liblsl to
its defaults (or the user's LSLAPICFG): every interface. Where the library cannot be built (no C compiler, not
Linux) the outlet still runs and its start-up line says which of its sockets other machines can reach, and why.
At start the outlet prints what its process listens on, read from /proc (`sockets`).

Timestamps are explicit: each sample carries its exposure's mid-exposure time, mapped from the device clock
to LSL's `local_clock` at the push: t_lsl = local_clock() - (device now - t_exposure) / speed (the clock is
the machine's monotonic clock, the same in both processes).

Limits: at most `MAX_PENDING` chunks wait for the process; beyond, a chunk is dropped and counted (`dropped`,
samples), so a stalled outlet never blocks the device thread. The process must say it is ready within
`START_TIMEOUT_S`.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import select
import subprocess
import sys
import threading
import time

import numpy as np

from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.lsl import wire
from eyehil.emulator.device.lsl.channels import block_rows, gaze_channels, metadata, relay_channels, relay_rows
from eyehil.emulator.device.lsl.library import LslUnavailableError, load_pylsl, ours
from eyehil.emulator.device.lsl.loopback import LibraryUnavailableError, library, preloaded
from eyehil.emulator.device.pupil.datums import EyeWindow
from eyehil.emulator.device.pupil.gaze import Block

LAYOUTS = ("eyehil", "pupil_relay")
BINDS = ("loopback", "all")
MAX_PENDING = 256  # chunks waiting for the outlet process (a chunk is one mapped block, about 10 ms)
START_TIMEOUT_S = 60.0  # the process imports numpy and pylsl and opens the outlet
STOP_TIMEOUT_S = 10.0


def stable_source_id(*identity: object) -> str:
    """``eyehil-<12 hex digits>`` of `identity` (the scene, eyes, head, address ... of a device): the same
    device gets the same id after a restart."""
    import hashlib

    return "eyehil-" + hashlib.sha256(repr(identity).encode()).hexdigest()[:12]


class OutletProcess:
    """The outlet process: started with its stream description, fed chunks by a writer thread."""

    def __init__(self, stream: dict, bind: str = "loopback") -> None:
        """Start the process for `stream` (see `process.open_outlet`) and wait until its outlet is open."""
        if bind not in BINDS:
            raise ValueError(f"LSL bind must be one of {BINDS}, got {bind!r}")
        env, self.library_note = dict(os.environ), ""
        if bind == "loopback":
            try:
                env = preloaded(env, library())
            except LibraryUnavailableError as exc:
                self.library_note = str(exc)
        elif ours(env.get("LSLAPICFG", "")):
            del env["LSLAPICFG"]  # liblsl's defaults; a configuration of the user's own is kept
        env["EYEHIL_LSL_LOOPBACK"] = "1" if bind == "loopback" else "0"
        self.bind, self.sent, self.dropped, self._closed = bind, 0, 0, False
        self._queue: queue.Queue[bytes | None] = queue.Queue(MAX_PENDING)
        self.proc = subprocess.Popen([sys.executable, "-m", "eyehil.emulator.device.lsl.process"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        try:
            self.proc.stdin.write(wire.frame({"stream": stream}))
            self.proc.stdin.flush()
            self.ready = self._ready()
        except BaseException:
            self._kill()
            raise
        self.pid: int = self.ready["pid"]
        self._writer = threading.Thread(target=self._write, name="lsl-outlet-writer", daemon=True)
        self._writer.start()

    def _ready(self) -> dict:
        deadline = time.monotonic() + START_TIMEOUT_S
        line = b""
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.proc.stdout], [], [], left)[0]:
                raise LslUnavailableError(f"the LSL outlet process did not start within {START_TIMEOUT_S:.0f} s")
            byte = os.read(self.proc.stdout.fileno(), 1)
            if not byte:
                raise LslUnavailableError(f"the LSL outlet process ended (status {self.proc.wait()}); "
                                          "its messages are on stderr")
            line += byte
        return json.loads(line)

    @property
    def listening(self) -> list[str]:
        """What the process listens on ("tcp 127.0.0.1:16572", ...), read at its start."""
        return list(self.ready["listening"])

    def exposure(self) -> str:
        """What the outlet binds, for the start-up message."""
        where = ", ".join(self.listening) or "unknown (no /proc)"
        out = f"LSL outlet (process {self.pid}) listens on {where}"
        beyond = self.ready["beyond_loopback"]
        if self.bind == "loopback" and beyond:
            why = self.library_note or "the loopback bind library did not take effect"
            out += f"; reachable from other machines: {', '.join(beyond)} ({why})"
        return out

    def send(self, rows: np.ndarray, stamps: np.ndarray) -> bool:
        """Queue a chunk; False (and counted in `dropped`) when `MAX_PENDING` chunks wait already or the
        process has ended."""
        if self.proc.poll() is None:
            try:
                self._queue.put_nowait(wire.frame(wire.chunk_message(rows, stamps)))
                self.sent += len(stamps)
                return True
            except queue.Full:
                pass
        self.dropped += len(stamps)
        return False

    def _write(self) -> None:
        while (data := self._queue.get()) is not None:
            try:
                self.proc.stdin.write(data)
                self.proc.stdin.flush()
            except (BrokenPipeError, ValueError, OSError):  # the process ended; `send` sees it
                return

    def close(self) -> None:
        """Let the process push what waits, end it, reap it; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._queue.put(None, timeout=STOP_TIMEOUT_S)
            self._writer.join(STOP_TIMEOUT_S)
        except queue.Full:
            pass
        with contextlib.suppress(OSError):
            self.proc.stdin.close()
        try:
            self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self._kill()
        self.proc.stdout.close()

    def _kill(self) -> None:
        self.proc.kill()
        self.proc.wait()


class GazeOutlet:
    """The outlet; `push` one `pupil.gaze.Block` at a time, `close` when done."""

    def __init__(self, windows: list[EyeWindow], n_leds: int, rate_hz: float, clock: Clock, *,
                 name: str = "eyehil", source_id: str | None = None, layout: str = "eyehil",
                 screen: tuple[np.ndarray, tuple[float, float]] | None = None, pupil_mm: float = float("nan"),
                 eye_centres: np.ndarray | None = None, bind: str = "loopback") -> None:
        """An outlet for the eyes of `windows` with `n_leds` glints each; `clock`: the device clock; `layout`
        "pupil_relay" (name ``pupil_capture``) needs `screen` (centre mm, size mm) and the pupil diameter, and
        takes the 3-D eye model's centres (`channels.relay_rows`); `bind`: "loopback" or "all" (see the module
        docstring)."""
        if layout not in LAYOUTS:
            raise ValueError(f"LSL layout must be one of {LAYOUTS}, got {layout!r}")
        self._lsl = load_pylsl()  # here only for local_clock: this process opens no LSL socket
        self.clock, self.layout, self.eye_ids = clock, layout, tuple(w.eye_id for w in windows)
        self.screen, self.pupil_mm, self.eye_centres = screen, pupil_mm, eye_centres
        if layout == "pupil_relay":
            name, self.channels = "pupil_capture", relay_channels()
        else:
            self.channels = gaze_channels(self.eye_ids, n_leds)
        stream = {"name": name, "type": "Gaze", "rate_hz": float(rate_hz), "source_id": source_id or name,
                  "manufacturer": "eyehil", "model": "eyehil virtual tracker, ZeroMQ facade",
                  "channels": metadata(self.channels)}
        self.process: OutletProcess | None = OutletProcess(stream, bind)
        print(self.process.exposure(), flush=True)

    @property
    def pushed(self) -> int:
        """Samples handed to the outlet process."""
        return self.process.sent if self.process else 0

    @property
    def counters(self) -> dict[str, int]:
        """lsl_samples (handed to the outlet process), lsl_dropped (not: the process fell behind or ended)."""
        return {"lsl_samples": self.pushed, "lsl_dropped": self.process.dropped if self.process else 0}

    def lsl_times(self, time_us: np.ndarray) -> np.ndarray:
        """LSL `local_clock` times (s) of device times (us), mapped now."""
        now_local, now_us = self._lsl.local_clock(), self.clock.now_us()
        speed = float(getattr(self.clock, "speed", 1.0))
        return now_local - (now_us - np.asarray(time_us, dtype=np.float64)) / 1e6 / speed

    def push(self, block: Block) -> None:
        """Push the block's samples with their explicit timestamps."""
        if self.process is None or len(block.time_us) == 0:
            return
        rows = (relay_rows(block, self.eye_ids, self.screen[0], self.screen[1], self.pupil_mm, self.eye_centres)
                if self.layout == "pupil_relay" else block_rows(block))
        self.process.send(rows, self.lsl_times(block.time_us))

    def close(self) -> None:
        """End the outlet process (its sockets and liblsl's threads); idempotent."""
        if self.process is not None:
            self.process.close()
            self.process = None
