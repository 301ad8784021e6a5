"""A recording folder of the ZeroMQ facade: what `R` ... `r` writes, in the files Pupil Capture writes.

Folder: `<record_dir>/<session>` (the first of `<session>`, `<session>_1`, ... `<session>_999` that does
not exist yet, so that an earlier recording of the same name is never overwritten), created by `open_folder`,
which refuses any folder that does not resolve inside `record_dir`.

Files (`Recording`):
- `info.player.json`: `recording_name`, `recording_uuid`, `recording_software_name` "eyehil",
  `recording_software_version`, `start_time_synced_s` (Pupil time), `start_time_system_s` (Unix time),
  `duration_s`; written at the start and again at the stop;
- `<kind>.pldata` and `<kind>_timestamps.npy` for the kinds `pupil`, `gaze`, `notify`, `annotation` (the
  first part of each datum's topic): Pupil's PLData format (pupil-labs/pupil
  `pupil_src/shared_modules/file_methods.py`, `PLData_Writer` and `load_pldata_file`): the .pldata file is a
  sequence of msgpack arrays ``[topic (str), datum (bin: the msgpack map of the datum, as published)]`` and
  the .npy file the datums' `timestamp`s (float64, Pupil time s) in the same order, written at the stop;
- `annotations.jsonl`: every annotation as one JSON line, written at once (eyehil's own).

Bounded: at most `budget.left` bytes of datums are written (the budget is shared by all the recordings of one
facade); datums past it are dropped and counted (`dropped`). Each timestamp kept in memory until the stop
costs 8 bytes, and every datum is larger than that. Writes are buffered (`BUFFER_BYTES` per file).
"""

from __future__ import annotations

import json
import math
import time
import uuid
from array import array
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, BinaryIO, TextIO

import msgpack
import numpy as np

KINDS = ("pupil", "gaze", "notify", "annotation")
BUFFER_BYTES = 1 << 20
MAX_SUFFIX = 999


def _version() -> str:
    """eyehil's installed version (as `eyehil.__version__`, which the emulator may not import)."""
    try:
        return version("eyehil")
    except PackageNotFoundError:
        return "0+unknown"


@dataclass
class Budget:
    """Bytes of datums that recordings may still write (all the recordings of one facade)."""

    left: int


def open_folder(record_dir: Path, name: str) -> Path:
    """A new, empty folder `<record_dir>/<name>[_k]` (see the module docstring); OSError if none can be made
    inside `record_dir`."""
    root = record_dir.resolve()
    for k in range(MAX_SUFFIX + 1):
        folder = record_dir / (name if k == 0 else f"{name}_{k}")
        if not folder.resolve().is_relative_to(root) or folder.resolve() == root:
            raise OSError(f"{folder} lies outside {record_dir}")
        try:
            folder.mkdir(parents=True, exist_ok=False)
        except FileExistsError:
            continue
        return folder
    raise OSError(f"{MAX_SUFFIX + 1} recordings named {name!r} exist already")


class _PLDataWriter:
    """One `<kind>.pldata` file and its timestamps."""

    def __init__(self, folder: Path, kind: str) -> None:
        self.folder, self.kind = folder, kind
        self.file: BinaryIO = (folder / f"{kind}.pldata").open("wb", buffering=BUFFER_BYTES)
        self.timestamps = array("d")

    def append(self, topic: str, datum: bytes, timestamp: float) -> int:
        """Write one datum; return the bytes written."""
        pair = msgpack.packb((topic, datum), use_bin_type=True)
        self.file.write(pair)
        self.timestamps.append(timestamp)
        return len(pair)

    def close(self) -> None:
        self.file.close()
        np.save(self.folder / f"{self.kind}_timestamps.npy", np.frombuffer(self.timestamps, dtype=np.float64))


class Recording:
    """An open recording folder; `add` datums, `annotation_line`s, then `close`. Raises OSError on I/O errors
    (the caller counts them)."""

    def __init__(self, folder: Path, name: str, start_synced_s: float, budget: Budget) -> None:
        """Write `info.player.json` and open the files in the new, empty `folder`."""
        self.folder, self.budget = folder, budget
        self.written = self.dropped = 0  # datums
        self.info: dict[str, Any] = {
            "recording_name": name, "recording_uuid": str(uuid.uuid4()), "recording_software_name": "eyehil",
            "recording_software_version": _version(), "start_time_synced_s": float(start_synced_s),
            "start_time_system_s": time.time(), "duration_s": 0.0}
        self._write_info()
        self._writers = {kind: _PLDataWriter(folder, kind) for kind in KINDS}
        self._jsonl: TextIO | None = (folder / "annotations.jsonl").open("a", encoding="utf-8")

    def add(self, topic: str, datum: bytes, timestamp: Any, now_s: float) -> None:
        """Record one datum (its msgpack bytes) under its kind (the topic's first part; other kinds are not
        recorded); `timestamp` that is not a finite number is replaced by `now_s`."""
        writer = self._writers.get(topic.split(".", 1)[0])
        if writer is None:
            return
        size = len(datum) + len(topic) + 16
        if size > self.budget.left:
            self.dropped += 1
            return
        ok = isinstance(timestamp, int | float) and not isinstance(timestamp, bool) and math.isfinite(timestamp)
        self.budget.left -= writer.append(topic, datum, float(timestamp) if ok else now_s)
        self.written += 1

    def annotation_line(self, text: str) -> None:
        """Append one JSON line to `annotations.jsonl` (flushed at once); counted in the budget."""
        if self._jsonl is None or len(text) + 1 > self.budget.left:
            self.dropped += self._jsonl is not None
            return
        self._jsonl.write(text + "\n")
        self._jsonl.flush()
        self.budget.left -= len(text) + 1

    def close(self, stop_synced_s: float) -> None:
        """Write the timestamps, close the files, write the duration into `info.player.json`; idempotent."""
        if self._jsonl is None:
            return
        self._jsonl.close()
        self._jsonl = None
        for writer in self._writers.values():
            writer.close()
        self.info["duration_s"] = float(stop_synced_s) - self.info["start_time_synced_s"]
        self._write_info()

    def _write_info(self) -> None:
        (self.folder / "info.player.json").write_text(json.dumps(self.info, indent=1), encoding="utf-8")
