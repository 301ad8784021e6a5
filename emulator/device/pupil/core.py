"""The device thread of the ZeroMQ facade: exposures become datums on the backbone; notifications steer it.

One thread ("eyehil-zmq-publisher") owns the camera (`eyehil.emulator.device.camera`), the subject's plan, the
`zmq_capture.Capture` state and two sockets: a PUB connected to the backbone's XSUB (everything this thread
publishes) and a SUB connected to its XPUB, subscribed to ``notify.`` and ``annotation`` (notifications and
annotations from Pupil Remote and from clients publishing directly). It wakes at the mid-exposure time of
each group of exposures due within `GROUP_S` (device clock: one exposure below 500 Hz, two at 1 kHz; waits
under a millisecond use an event's timeout, not the socket poll) and whenever a message arrives, and per
exposure publishes ``pupil.<id>.2d`` and ``glint.<id>`` of every tracked
eye (`zmq_datums`), hands every k-th exposure to the frame thread (`zmq_frames`) and every k_w-th, with the
target then on the screen (`world.TargetTrack`), to the world thread (`pupil/world.py`), and queues it for gaze
mapping (`zmq_gaze`) and the LSL outlet. Falling more than `MAX_BEHIND_S` behind, it skips the excess
exposures (counted in ``exposures_skipped``) instead of bursting them.

Malformed messages from the backbone (`eyehil.protocols.pupil.unpack` refuses them) are dropped and counted.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from typing import Any

import numpy as np
import zmq

from eyehil.emulator.device.camera import Camera, Exposures, Selection
from eyehil.emulator.device.clock import Clock
from eyehil.emulator.device.pupil.capture import Capture
from eyehil.emulator.device.pupil.datums import EyeWindow, PupilTime, exposure_datums, sample_arrays
from eyehil.emulator.device.pupil.eye3d import EyeModel3d, pupil_3d_datums
from eyehil.emulator.device.pupil.frames import FramePublisher
from eyehil.emulator.device.pupil.gaze import BATCH_S, GazeStream
from eyehil.emulator.device.pupil.world import TargetTrack, WorldPublisher
from eyehil.emulator.device.subject import Subject
from eyehil.protocols.enums import Eye
from eyehil.protocols.pupil import PupilMessageError, pack, unpack

MAX_BEHIND_S = 0.25
GROUP_S = 0.002  # exposures due within this long are published together (s): at most 1 ms more latency at 1 kHz
IDLE_S = 0.05
DRAIN = 256  # messages handled per wake-up at most
RECORDED = ("pupil.", "gaze.")  # what the device publishes that a recording keeps (notifications come back)


class DeviceThread:
    """See the module docstring; `start`, then `close` (joins the thread, closes its sockets)."""

    def __init__(self, context: zmq.Context, endpoint: str, sub: zmq.Socket, subject: Subject, clock: Clock,
                 time: PupilTime, windows: list[EyeWindow], capture: Capture, *, rate_hz: int,
                 frames: FramePublisher | None = None, frame_every: int = 1, outlet: Any = None,
                 hwm: int = 1000, surface_name: str = "screen", world: WorldPublisher | None = None,
                 world_every: int = 1) -> None:
        """Publish to the XSUB at `endpoint`; `sub`: the SUB already connected and subscribed (the server
        checked that messages reach it)."""
        scene = subject.solver.scene
        self.subject, self.clock, self.time, self.windows = subject, clock, time, windows
        self.capture, self.frames, self.frame_every, self.outlet = capture, frames, frame_every, outlet
        self.rate_hz = rate_hz
        self.world, self.world_every, self.targets = world, world_every, TargetTrack()
        tracked = tuple(Eye(w.eye_id) for w in windows)
        self.camera = Camera(subject, tuple(int(v) for v in scene.camera.resolution_px), tracked)
        self._selection = Selection(tracked, len(scene.leds))
        self.eye3d = EyeModel3d.of(subject.solver)
        self.gaze = GazeStream(windows, time, scene.screen.size, eye3d=self.eye3d, screen_centre=scene.screen.centre,
                               surface_name=surface_name)
        self.counters: Counter[str] = Counter()
        self._seq: Counter[str] = Counter()  # per topic, the next sequence number
        self.failure: Exception | None = None
        self._sub = sub
        self._pub = context.socket(zmq.PUB)
        self._pub.setsockopt(zmq.LINGER, 0)
        self._pub.setsockopt(zmq.SNDHWM, hwm)
        self._pub.connect(endpoint)
        self._poller = zmq.Poller()
        self._poller.register(sub, zmq.POLLIN)
        self._stop = threading.Event()
        self.stepped = threading.Condition()  # notified after every turn of the loop (PupilServer.wait_until)
        self._thread = threading.Thread(target=self._run, name="eyehil-zmq-publisher", daemon=True)

    def show(self, screen_mm: tuple[float, float], t_us: int) -> None:
        """The subject looks at `screen_mm` from device time `t_us` (the `Capture`'s stand-in for the screen)."""
        self.camera.invalidate(self.subject.look_at(screen_mm, t_us))
        self.targets.shown(screen_mm, t_us)

    def start(self) -> None:
        """Start exposing now and the thread."""
        self.camera.start(self.clock.now_us(), self.rate_hz, self._selection)
        self._thread.start()

    # --- the loop ----------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._receive(self._wait_s())
                self._emit()
                if self.gaze.due(self.clock.now_us()):
                    self._map()
                self._publish(self.capture.poll())
                with self.stepped:
                    self.stepped.notify_all()
        except Exception as exc:  # a bug: the device stops, loudly, instead of hanging its clients
            self.failure = exc
            logging.getLogger(__name__).exception("the ZeroMQ device thread stopped")
        finally:
            self._pub.close(linger=0)
            self._sub.close(linger=0)

    def _wait_s(self) -> float:
        """Wall seconds until the next group of exposures is due (at most `IDLE_S`; less while a fit or gaze
        waits): the exposures due within `GROUP_S` go out together (at 1 kHz in pairs, below 500 Hz one by one),
        which spares the thread a wake-up per exposure."""
        group = max(1, int(self.rate_hz * GROUP_S))
        due_us = self.camera.time_of(self.camera.taken + group - 1)
        wait = min(IDLE_S, self.clock.wall_delay_s(due_us))
        return min(wait, BATCH_S) if self.capture.gazer is not None or self.outlet is not None else wait

    def _receive(self, wait_s: float) -> None:
        """Wait up to `wait_s` for messages; handle those that arrived."""
        if wait_s >= 0.001:
            if not self._poller.poll(int(wait_s * 1000)):
                return
        elif wait_s > 0:
            self._stop.wait(wait_s)
        for _ in range(DRAIN):
            try:
                frames = self._sub.recv_multipart(zmq.NOBLOCK)
            except zmq.Again:
                return
            self._handle(frames)

    def _handle(self, frames: list[bytes]) -> None:
        self.counters["messages_received"] += 1
        try:
            topic, payload = unpack(frames)
        except PupilMessageError:
            self.counters["messages_malformed"] += 1
            return
        self._publish(self.capture.on_message(topic, payload))

    def _publish(self, payloads: list[dict[str, Any]], built: bool = False) -> None:
        """Publish, each payload with its topic's sequence number `seq` (0, 1, 2 ... per topic; an extra key
        Pupil clients ignore, so that a subscriber tells skipped from dropped); pupil and gaze datums also go to
        a recording under way (`Capture.record`; notifications come back through the SUB and are recorded there).
        `built`: the datums of exposures, built here from literal keys, so their keys go unchecked (`pack`)."""
        for payload in payloads:
            topic = payload["topic"]
            payload["seq"] = self._seq[topic]
            self._seq[topic] += 1
            frames = pack(payload, check_keys=not built)
            self._pub.send_multipart(frames)
            if topic.startswith(RECORDED):
                self.capture.record(topic, frames[1], payload.get("timestamp"))
        self.counters["published"] += len(payloads)

    # --- exposures -------------------------------------------------------------------------------
    def _emit(self) -> None:
        """Publish the exposures due."""
        due = self.camera.due(self.clock.now_us())
        behind = due - max(1, round(self.rate_hz * MAX_BEHIND_S))
        if behind > 0:
            self.camera.skip(behind)
            self.counters["exposures_skipped"] += behind
            due -= behind
        if due <= 0:
            return
        exp = self.camera.take(due)
        pupils, pupils_3d = [], []
        datums_2d = exposure_datums(exp, self.windows, self.time)
        found = np.array([[d["confidence"] > 0 for d in datums[0::2]] for datums in datums_2d])
        datums_3d = pupil_3d_datums(exp.batch.centre, found, self.eye3d, self.windows,
                                    [datums[0::2] for datums in datums_2d])
        for n in range(len(exp)):
            self._publish(datums_2d[n], built=True)
            self._publish(datums_3d[n], built=True)
            pupils.append(datums_2d[n][0::2])
            pupils_3d.append(datums_3d[n])
            self._offer_frame(exp, n)
        self.counters["exposures"] += len(exp)
        if self.capture.session is not None:
            self.capture.session.add_samples(np.asarray(self.time.of_us(exp.time_us)), *sample_arrays(exp))
        if self.capture.gazer is not None or self.outlet is not None:
            self.gaze.add(exp, pupils, pupils_3d)

    def _offer_frame(self, exp: Exposures, n: int) -> None:
        frame_id = int(exp.batch.frame_id[n])
        if not self.capture.frames_on:
            return
        if self.world is not None and frame_id % self.world_every == 0:
            t_us = int(exp.time_us[n])
            self.world.offer(float(self.time.of_us(t_us)), self.targets.at(t_us, self.subject.timeline),
                             self.capture.frame_format)
        if self.frames is None or frame_id % self.frame_every:
            return
        self.frames.offer(frame_id, float(self.time.of_us(int(exp.time_us[n]))), exp.values[n],
                          bool(exp.blink[n]), self.capture.frame_format)

    def _map(self) -> None:
        """Map the waiting exposures to gaze; feed the LSL outlet."""
        datums, block = self.gaze.flush(self.capture.gazer)
        self._publish(datums)
        if self.outlet is not None and block is not None:
            self.outlet.push(block)

    def close(self) -> None:
        """Stop and join the thread (it closes its sockets)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        elif not self._pub.closed:
            self._pub.close(linger=0)
            self._sub.close(linger=0)
