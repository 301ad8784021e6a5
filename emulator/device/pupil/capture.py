"""What Pupil Capture does with the messages on its backbone, for the ZeroMQ facade: no sockets, no threads.

`Capture.on_message(topic, payload)` reacts to one message and returns the payloads to publish:

- ``notify.calibration.should_start`` -> ``calibration.started``; a new `zmq_calibration.Session`;
- ``notify.calibration.add_ref_data {ref_data: [{norm_pos, timestamp}, ...]}``: reference data (screen,
  normalised, origin bottom-left; Pupil time); a new target position also makes the simulated subject look
  there at its first timestamp (or now, if that is past): the emulator's stand-in for the screen (at most
  `MAX_TARGETS` new positions per message and per calibration);
- ``notify.eyehil.stimulus {norm_pos, timestamp?}`` (this emulator's own): show a target without reference
  data; during a calibration it is a target until the next one;
- ``notify.calibration.should_stop`` -> ``calibration.stopped``, then (the fit runs on a worker thread;
  `poll` returns the outcome) ``calibration.successful`` and ``calibration.result.v2 {gazer_class_name,
  params}``, or ``calibration.failed {reason}``; gaze is then mapped with the new gazer;
- ``notify.frame_publishing.set_format {format}`` and ``notify.start_plugin {name: "Frame_Publisher",
  args: {format}}`` -> ``frame_publishing.started {format}``; ``notify.stop_plugin {name:
  "Frame_Publisher"}`` -> ``frame_publishing.stopped``;
- ``notify.recording.should_start {session_name}`` / ``should_stop`` -> ``recording.started`` / ``stopped``;
- ``annotation``: kept (`annotations`, the latest `MAX_ANNOTATIONS`), and while recording into a directory,
  appended to ``<record_dir>/<session>/annotations.jsonl`` (one JSON object per line).

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
from typing import Any, TextIO

from eyehil.emulator.device.pupil.calibration import MAX_TARGETS, Gazer, Session, fit, norm_to_screen
from eyehil.emulator.device.pupil.datums import PupilTime
from eyehil.emulator.device.stimulus import stimulus_problem
from eyehil.emulator.scene import Scene
from eyehil.protocols.pupil import FRAME_FORMATS, RAW, norm_pos_of, notification, parse_ref_data

MAX_ANNOTATIONS = 100_000
FRAME_PUBLISHER = "Frame_Publisher"


def _number(value: Any) -> float | None:
    """A finite float, or None."""
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return float(value) if ok else None


class Capture:
    """The state of the emulated Pupil Capture; see the module docstring. Used by one thread only."""

    def __init__(self, scene: Scene, eye_ids: tuple[int, ...], time: PupilTime,
                 show: Callable[[tuple[float, float], int], None], *, settle_s: float = 0.35,
                 frame_format: str = "gray", record_dir: str | Path | None = None) -> None:
        """`show(screen_mm, t_us)` makes the subject look at a screen point from device time `t_us`."""
        self.scene, self.eye_ids, self.time, self.show = scene, eye_ids, time, show
        self.settle_s = settle_s
        self.frame_format, self.frames_on = frame_format, True
        self.record_dir = Path(record_dir) if record_dir else None
        self.session: Session | None = None
        self.gazer: Gazer | None = None
        self.recording: str | None = None
        self._annotations: deque[dict[str, Any]] = deque(maxlen=MAX_ANNOTATIONS)
        self._lock = threading.Lock()  # annotations are read by other threads
        self.counters: Counter[str] = Counter()
        self._shown: tuple[float, float] | None = None
        self._file: TextIO | None = None
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
            return self._annotation(payload)
        subject = payload.get("subject")
        if not topic.startswith("notify.") or not isinstance(subject, str):
            return []
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
        return [self._note("calibration.started")]

    def _calibration_stop(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if self.session is None:
            self.counters["stop_without_start"] += 1
            return []
        fixations, self.session = self.session.fixations(self.time.now()), None
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="eyehil-zmq-fit")
        self._fit = self._executor.submit(fit, fixations, self.scene, self.eye_ids)
        return [self._note("calibration.stopped")]

    def poll(self) -> list[dict[str, Any]]:
        """The outcome of a finished calibration fit (successful + result.v2, or failed), once."""
        if self._fit is None or not self._fit.done():
            return []
        outcome, self._fit = self._fit.result(), None
        if isinstance(outcome, str):
            return [self._note("calibration.failed", reason=outcome)]
        self.gazer = outcome
        return [self._note("calibration.successful", method=outcome.class_name),
                self._note("calibration.result.v2", gazer_class_name=outcome.class_name, params=outcome.params)]

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
            folder = self.record_dir / self.recording
            try:
                folder.mkdir(parents=True, exist_ok=True)
                self._file = (folder / "annotations.jsonl").open("a", encoding="utf-8")
                path = str(folder)
            except OSError:
                self.counters["recording_errors"] += 1
        return [self._note("recording.started", session_name=self.recording, rec_path=path,
                           start_time_synced_s=self.time.now())]

    def _recording_stop(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        if self.recording is None:
            return []
        name, self.recording = self.recording, None
        self._close_file()
        return [self._note("recording.stopped", session_name=name)]

    def _annotation(self, payload: dict[str, Any]) -> list[dict[str, Any]]:
        record = {k: v for k, v in payload.items() if k != RAW}
        record["recording"] = self.recording
        with self._lock:
            self._annotations.append(record)
        self.counters["annotations"] += 1
        if self._file is not None:
            try:
                self._file.write(json.dumps(record, default=repr) + "\n")
                self._file.flush()
            except OSError:
                self.counters["recording_errors"] += 1
        return []

    @property
    def annotations(self) -> list[dict[str, Any]]:
        """A copy of the annotations kept (any thread)."""
        with self._lock:
            return list(self._annotations)

    def _close_file(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def close(self) -> None:
        """Stop the fit worker and close the annotation file."""
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None
        self._close_file()
