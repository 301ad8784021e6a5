"""What Pupil Capture does with the messages on its backbone, for the ZeroMQ facade: no sockets, no threads.

`Capture.on_message(topic, payload)` reacts to one message and returns the payloads to publish:

- ``notify.calibration.should_start`` -> ``calibration.started``; a new `zmq_calibration.Session` with a
  screen-marker calibration (`_markers`) that stops by itself unless a client shows its own targets;
- ``notify.calibration.add_ref_data {ref_data: [{norm_pos, timestamp}, ...]}``: reference data (screen,
  normalised, origin bottom-left; Pupil time); a new target position also makes the simulated subject look
  there at its first timestamp (or now, if that is past): the emulator's stand-in for the screen (at most
  `MAX_TARGETS` new positions per message and per calibration);
- ``notify.eyehil.stimulus {norm_pos, timestamp?}`` (this emulator's own): show a target without reference
  data; during a calibration it is a target until the next one;
- ``notify.calibration.should_stop``: the fit runs on a worker thread; `poll` returns the outcome,
  ``calibration.successful`` and ``calibration.result.v2 {gazer_class_name, params}``, or
  ``calibration.failed {reason}``, then ``calibration.stopped`` (Pupil Capture sends ``stopped`` first; the
  PsychoPy ioHub Pupil Labs backend takes a ``stopped`` before ``successful`` for an aborted setup); gaze is
  then mapped with the new gazer;
- ``notify.frame_publishing.set_format {format}`` and ``notify.start_plugin {name: "Frame_Publisher",
  args: {format}}`` -> ``frame_publishing.started {format}``; ``notify.stop_plugin {name:
  "Frame_Publisher"}`` -> ``frame_publishing.stopped``;
- ``notify.recording.should_start {session_name}`` / ``should_stop`` -> ``recording.started`` / ``stopped``;
- ``annotation``: kept (`annotations`: the latest `MAX_ANNOTATIONS` within `MAX_ANNOTATIONS_BYTES` of JSON
  text; one over `MAX_ANNOTATION_BYTES` is refused).

While a recording runs with a `record_dir`, its folder (`recorder.Recording`, never outside `record_dir`)
receives the notifications and annotations that arrive here and, through `record`, the pupil and gaze datums
the device thread publishes, within `record_max_bytes` for all the recordings of the facade.

Anything else is ignored. `counters` counts what was refused.
"""

from __future__ import annotations

import json
import math
import re
import threading
from collections import Counter, deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.emulator.device.pupil.calibration import MAX_TARGETS, Gazer, Session, fit, norm_to_screen
from eyehil.emulator.device.pupil.datums import PupilTime
from eyehil.emulator.device.pupil.recorder import Budget, Recording, open_folder
from eyehil.emulator.device.stimulus import stimulus_problem
from eyehil.emulator.scene import Scene
from eyehil.protocols.pupil import (
    FRAME_FORMATS,
    RAW,
    PupilMessageError,
    norm_pos_of,
    notification,
    pack,
    parse_ref_data,
)

MAX_ANNOTATIONS = 100_000
MAX_ANNOTATION_BYTES = 1 << 20  # one annotation (its JSON text); larger ones are refused
MAX_ANNOTATIONS_BYTES = 64 << 20  # all kept annotations; the oldest go first
MARKER_S = 1.0  # the screen-marker calibration: each marker shown this long
MARKER_LEAD_S = 0.3  # ... the first one this long after `C`
MAX_MARKERS = 9
FRAME_PUBLISHER = "Frame_Publisher"
RECORD_MAX_BYTES = 1 << 30  # datums all the recordings of one facade may write


def _number(value: Any) -> float | None:
    """A finite float, or None."""
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return float(value) if ok else None


class Capture:
    """The state of the emulated Pupil Capture; see the module docstring. Used by one thread only."""

    def __init__(self, scene: Scene, eye_ids: tuple[int, ...], time: PupilTime,
                 show: Callable[[tuple[float, float], int], None], *, settle_s: float = 0.35,
                 frame_format: str = "gray", record_dir: str | Path | None = None,
                 record_max_bytes: int = RECORD_MAX_BYTES) -> None:
        """`show(screen_mm, t_us)` makes the subject look at a screen point from device time `t_us`."""
        self.scene, self.eye_ids, self.time, self.show = scene, eye_ids, time, show
        self.settle_s = settle_s
        self.frame_format, self.frames_on = frame_format, True
        self.record_dir = Path(record_dir) if record_dir else None
        self.session: Session | None = None
        self.gazer: Gazer | None = None
        self.recording: str | None = None
        self._annotations: deque[tuple[dict[str, Any], int]] = deque()  # (annotation, its size in bytes)
        self._annotation_bytes = 0
        self._markers_stop_s: float | None = None  # a screen-marker calibration runs until then
        self._marker_queue: list[tuple[tuple[float, float], float]] = []  # markers still to show (mm, onset s)
        self._lock = threading.Lock()  # annotations are read by other threads
        self.counters: Counter[str] = Counter()
        self._shown: tuple[float, float] | None = None
        self._recorder: Recording | None = None
        self._budget = Budget(record_max_bytes)
        self._fit: Future | None = None
        self._executor: ThreadPoolExecutor | None = None
        self._handlers: dict[str, Callable[[dict[str, Any]], list[dict[str, Any]]]] = {
            "calibration.should_start": self._calibration_start, "calibration.should_stop": self._calibration_stop,
            "calibration.add_ref_data": self._add_ref_data, "eyehil.stimulus": self._stimulus,
            "frame_publishing.set_format": self._set_format, "start_plugin": self._start_plugin,
            "stop_plugin": self._stop_plugin, "recording.should_start": self._recording_start,
            "recording.should_stop": self._recording_stop}

    # --- dispatch -------------------------------------------------------------------------
    def on_message(self, topic: str, payload: dict[str, Any]) -> list[dict[str, Any]]:
        """React to one message from the backbone; return the payloads to publish."""
        if topic == "annotation" or topic.startswith("annotation."):
            return self._annotation(topic, payload)
        subject = payload.get("subject")
        if not topic.startswith("notify.") or not isinstance(subject, str):
            return []
        self._record_received(topic, payload)
        handler = self._handlers.get(subject)
        return handler(payload) if handler else []

    def _note(self, subject: str, **fields: Any) -> dict[str, Any]:
        return notification(subject, timestamp=self.time.now(), **fields)

    # --- targets ----------------------------------------------------------------------------
    def _screen_mm(self, norm: tuple[float, float]) -> tuple[float, float] | None:
        """Scene screen mm of a normalised position, or None (counted) if it lies too far off the screen."""
        width, height = self.scene.screen.size
        if stimulus_problem(self.scene.screen, norm[0] * width, (1.0 - norm[1]) * height):
            self.counters["targets_refused"] += 1
            return None
        x, y = norm_to_screen((width, height), norm)
        return float(x), float(y)

    def _look(self, screen: tuple[float, float], t_s: float) -> float:
        """Show `screen` from Pupil time `t_s` (or now, if that is past); return when (Pupil time)."""
        t_us = max(self.time.clock.now_us(), self.time.to_us(t_s))
        if screen != self._shown:
            self.show(screen, t_us)
            self._shown = screen
        return float(self.time.of_us(t_us))

    def _add_ref_data(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        self._client_targets()
        refs, refused = parse_ref_data(payload)
        self.counters["ref_data_refused"] += refused
        shown = 0
        for ref in refs:
            screen = self._screen_mm(ref.norm_pos)
            if screen is None:
                continue
            new = self.session.add_ref(screen, ref.timestamp) if self.session else screen != self._shown
            if new is None or (new and shown >= MAX_TARGETS):
                self.counters["targets_refused"] += 1
            elif new:
                self._look(screen, ref.timestamp)
                shown += 1
        return []

    def _stimulus(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        self._client_targets()
        norm, ts = norm_pos_of(payload), _number(payload.get("timestamp", self.time.now()))
        if norm is None or ts is None:
            self.counters["targets_refused"] += 1
            return []
        screen = self._screen_mm(norm)
        if screen is None:
            return []
        if self.session and len(self.session.targets) >= MAX_TARGETS:
            self.counters["targets_refused"] += 1
            return []
        self._shown = None  # a stimulus always (re)starts a target
        onset = self._look(screen, ts)
        if self.session:
            self.session.add_stimulus(screen, onset)
        return []

    # --- calibration ------------------------------------------------------------------------
    def _calibration_start(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        self.session, self._shown = Session(self.settle_s), None
        self._markers()
        return [self._note("calibration.started")]

    def _markers(self) -> None:
        """Pupil Capture's screen-marker calibration: the scene's targets (at most 3 x 3 of its grid), each
        shown for MARKER_S from MARKER_LEAD_S on; the subject looks at each; the calibration stops by itself
        after the last (`poll`). Reference data or a stimulus from a client replace it (`_client_targets`)."""
        screen = self.scene.screen
        cols, rows = screen.grid
        grid = screen.targets().reshape(cols, rows, 3)
        pick_c = np.unique(np.linspace(0, cols - 1, min(cols, 3)).round()).astype(int)
        pick_r = np.unique(np.linspace(0, rows - 1, min(rows, 3)).round()).astype(int)
        points = [screen.to_screen(grid[c, r]) for r in pick_r for c in pick_c][:MAX_MARKERS]
        start = self.time.now() + MARKER_LEAD_S
        for k, p in enumerate(points):
            xy, onset = (float(p[0]), float(p[1])), start + k * MARKER_S
            self.session.add_ref(xy, onset)
            self.session.add_ref(xy, onset + MARKER_S - 0.05)
            self._marker_queue.append((xy, onset))
        self._markers_stop_s = start + len(points) * MARKER_S

    def _client_targets(self) -> None:
        """A client shows its own targets: the screen markers of this session are dropped."""
        if self._markers_stop_s is not None and self.session is not None:
            self.session, self._markers_stop_s = Session(self.settle_s), None
            self._marker_queue.clear()

    def _calibration_stop(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if self.session is None:
            self.counters["stop_without_start"] += 1
            return []
        fixations, self.session, self._markers_stop_s = self.session.fixations(self.time.now()), None, None
        self._marker_queue.clear()
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eyehil-zmq-fit")
        self._fit = self._executor.submit(fit, fixations, self.scene, self.eye_ids)
        return []  # calibration.stopped follows the outcome (`poll`)

    def poll(self) -> list[dict[str, Any]]:
        """The end of a screen-marker calibration (calibration.stopped), or the outcome of a finished fit
        (successful + result.v2, or failed), once."""
        now = self.time.now()
        while self._marker_queue and self._marker_queue[0][1] <= now + MARKER_LEAD_S / 2:
            xy, onset = self._marker_queue.pop(0)  # each marker when its time comes: one solve at a time
            self.show(xy, self.time.to_us(onset))
        if self._markers_stop_s is not None and now >= self._markers_stop_s:
            return self._calibration_stop({})
        if self._fit is None or not self._fit.done():
            return []
        outcome, self._fit = self._fit.result(), None
        if isinstance(outcome, str):
            return [self._note("calibration.failed", reason=outcome), self._note("calibration.stopped")]
        self.gazer = outcome
        return [self._note("calibration.successful", method=outcome.class_name),
                self._note("calibration.result.v2", gazer_class_name=outcome.class_name, params=outcome.params),
                self._note("calibration.stopped")]

    # --- frames -------------------------------------------------------------------------------
    def _set_format(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        fmt = payload.get("format")
        if fmt not in FRAME_FORMATS:
            self.counters["frame_formats_refused"] += 1
            return []
        self.frame_format, self.frames_on = fmt, True
        return [self._note("frame_publishing.started", format=fmt)]

    def _start_plugin(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if payload.get("name") != FRAME_PUBLISHER:
            return []
        args = payload.get("args")
        fmt = args.get("format", self.frame_format) if isinstance(args, dict) else self.frame_format
        return self._set_format({"format": fmt})

    def _stop_plugin(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if payload.get("name") != FRAME_PUBLISHER or not self.frames_on:
            return []
        self.frames_on = False
        return [self._note("frame_publishing.stopped")]

    # --- recording and annotations --------------------------------------------------------------
    def _recording_start(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if self.recording is not None:
            return []
        name = payload.get("session_name")
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:100].strip(".") if isinstance(name, str) else ""
        self.recording = name or f"recording_{self.time.now():.3f}".replace(".", "_")
        path = ""
        if self.record_dir is not None:
            try:
                folder = open_folder(self.record_dir, self.recording)
                self._recorder = Recording(folder, self.recording, self.time.now(), self._budget)
                path = str(folder)
            except OSError:
                self.counters["recording_errors"] += 1
        return [self._note("recording.started", session_name=self.recording, rec_path=path,
                           start_time_synced_s=self.time.now())]

    def _recording_stop(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if self.recording is None:
            return []
        name, self.recording = self.recording, None
        self._close_recorder()
        return [self._note("recording.stopped", session_name=name)]

    def record(self, topic: str, datum: bytes, timestamp: Any) -> None:
        """While a recording runs into a folder: record a datum published by the device (its msgpack bytes)."""
        if self._recorder is not None:
            try:
                self._recorder.add(topic, datum, timestamp, self.time.now())
            except OSError:
                self.counters["recording_errors"] += 1
                self._close_recorder()

    def _record_received(self, topic: str, payload: dict[str, Any]) -> None:
        """Record a notification or annotation from the backbone (without its raw frames)."""
        if self._recorder is not None:
            try:
                datum = pack({k: v for k, v in payload.items() if k != RAW})[1]
            except PupilMessageError:
                self.counters["recording_errors"] += 1
                return
            self.record(topic, datum, payload.get("timestamp"))

    def _close_recorder(self) -> None:
        if self._recorder is None:
            return
        recorder, self._recorder = self._recorder, None
        self.counters["recorded"] += recorder.written
        self.counters["recorded_dropped"] += recorder.dropped
        try:
            recorder.close(self.time.now())
        except OSError:
            self.counters["recording_errors"] += 1

    def _annotation(self, topic: str, payload: dict[str, Any]) -> list[dict[str, Any]]:
        record = {k: v for k, v in payload.items() if k != RAW}
        record["recording"] = self.recording
        text = json.dumps(record, default=repr)
        if len(text) > MAX_ANNOTATION_BYTES:
            self.counters["annotations_refused"] += 1
            return []
        with self._lock:
            self._annotations.append((record, len(text)))
            self._annotation_bytes += len(text)
            while len(self._annotations) > MAX_ANNOTATIONS or self._annotation_bytes > MAX_ANNOTATIONS_BYTES:
                self._annotation_bytes -= self._annotations.popleft()[1]
                self.counters["annotations_evicted"] += 1
        self.counters["annotations"] += 1
        self._record_received(topic, payload)
        if self._recorder is not None:
            try:
                self._recorder.annotation_line(text)
            except OSError:
                self.counters["recording_errors"] += 1
        return []

    @property
    def annotations(self) -> list[dict[str, Any]]:
        """A copy of the annotations kept (any thread)."""
        with self._lock:
            return [a for a, _ in self._annotations]

    def close(self) -> None:
        """Stop the fit worker and finish a recording under way."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        self._close_recorder()
