"""Recordings: samples with device and host timestamps, the configuration and target labels, in JSON Lines.

Format (docs/recording.md): UTF-8, one JSON object per line; the first line is the header, then
"target" and "sample" records in arrival order, then one "end" record. A file cut short (the host
crashed) lacks the end record and may end with a partial line: `read_recording` keeps every complete
record and reports ``complete=False``.

    with Recorder("run.jsonl", tracker) as rec:        # header: device info, configuration, clock sync
        rec.target(1, 188.5, 150.5, device_us=ack_us)    # a target shown (mm, top-left origin)
        for sample in tracker.samples(count=1000):
            rec.write(sample)
    data = read_recording("run.jsonl")                   # numpy arrays, see `Recording`
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.drivers.wire import Sample, host_now_us
from eyehil.protocols.replies import Status

FORMAT = "eyehil-recording"
VERSION = 1


class RecordingError(ValueError):
    """A recording file is not in the format (names the line)."""


def _eye_record(e) -> dict[str, Any]:
    return {"eye": int(e.eye), "flags": int(e.flags), "centre": [e.centre_x, e.centre_y], "axes": [e.axis_a, e.axis_b],
            "angle_deg": e.angle_deg, "confidence": e.confidence,
            "glints": [{"led": g.led, "flags": int(g.flags), "x": g.x, "y": g.y} for g in e.glints]}


def _plain(value: Any) -> Any:
    """Enums and dataclasses as JSON values."""
    if hasattr(value, "__dataclass_fields__"):
        return {k: _plain(v) for k, v in asdict(value).items()}
    return int(value) if isinstance(value, int) else value


class Recorder:
    """Writes one recording; see the module docstring. `tracker` supplies the header (after its handshake)."""

    def __init__(self, path: str | Path, tracker, *, clock_sync=None, note: str = "") -> None:
        """Create `path` and write the header."""
        self.path = Path(path)
        self._file = self.path.open("w", encoding="utf-8")
        self._target: int | None = None
        self._targets: list[tuple[int, int | None]] = []  # (device_us, id or None), pending until samples pass
        self.samples = 0
        info = tracker.info
        self._line({"format": FORMAT, "version": VERSION, "created": datetime.now(UTC).isoformat(),
                    "url": getattr(tracker, "url", ""), "note": note, "device": _plain(info),
                    "configuration": _plain(getattr(tracker, "configuration", None)),
                    "clock_sync": _plain(clock_sync), "host_clock": "monotonic, us"})

    def _line(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")

    def target(self, target_id: int, x_mm: float, y_mm: float, *, device_us: int, visible: bool = True,
               label: str = "") -> None:
        """A target was shown (or hidden) at device time `device_us`; samples from then on carry its id."""
        self._line({"type": "target", "host_us": host_now_us(), "device_us": device_us, "target_id": target_id,
                    "x_mm": x_mm, "y_mm": y_mm, "visible": visible, "label": label})
        self._targets.append((device_us, target_id if visible else None))

    def write(self, sample: Sample) -> None:
        """Append one sample, labelled with the target shown at its exposure time."""
        while self._targets and self._targets[0][0] <= sample.device_us:
            self._target = self._targets.pop(0)[1]
        self._line({"type": "sample", "seq": sample.seq, "frame_id": sample.frame_id, "device_us": sample.device_us,
                    "host_us": sample.host_us, "lost_before": sample.lost_before,
                    "skipped_before": sample.skipped_before, "target_id": self._target,
                    "eyes": [_eye_record(e) for e in sample.eyes]})
        self.samples += 1

    def close(self, stats: dict[str, int] | None = None, status: Status | None = None) -> None:
        """Write the end record (host counters, the device's STATUS) and close; idempotent."""
        if self._file.closed:
            return
        self._line({"type": "end", "host_us": host_now_us(), "samples": self.samples, "stats": stats or {},
                    "status": _plain(status)})
        self._file.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class Recording:
    """A recording read back. Per sample (N): seq, frame_id, device_us, host_us, lost_before, target_id
    (-1 = none); per sample and eye (N, E, ...): pupil_flags, centre (px), axes (px), angle_deg,
    confidence, glint_flags (N, E, L), glints (N, E, L, 2) px; eyes (E,) the eye ids (0 right, 1 left)."""

    header: dict[str, Any]
    targets: list[dict[str, Any]]
    end: dict[str, Any] | None
    arrays: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """False if the file lacks its end record (the recording was cut short)."""
        return self.end is not None

    def __getattr__(self, name: str) -> np.ndarray:
        arrays = self.__dict__.get("arrays", {})
        if name in arrays:
            return arrays[name]
        raise AttributeError(name)

    def __len__(self) -> int:
        return len(self.arrays["seq"])


def _parse(lines: list[str], path: Path) -> tuple[dict, list[dict], list[dict], dict | None]:
    """Header, targets, samples, end; a broken LAST line is tolerated (a cut-short file)."""
    records = []
    for number, line in enumerate(lines, 1):
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError as exc:
            if number == len(lines):
                break
            raise RecordingError(f"{path}:{number}: not JSON: {exc}") from exc
    if not records or records[0].get("format") != FORMAT or records[0].get("version") != VERSION:
        raise RecordingError(f"{path}: not an {FORMAT} version {VERSION} file")
    kinds = {"target": [], "sample": [], "end": []}
    for number, record in enumerate(records[1:], 2):
        if record.get("type") not in kinds:
            raise RecordingError(f"{path}:{number}: unknown record type {record.get('type')!r}")
        kinds[record["type"]].append(record)
    return records[0], kinds["target"], kinds["sample"], (kinds["end"] or [None])[-1]


def _arrays(samples: list[dict]) -> dict[str, np.ndarray]:
    n = len(samples)
    n_eyes = max((len(s["eyes"]) for s in samples), default=0)
    n_glints = max((len(e["glints"]) for s in samples for e in s["eyes"]), default=0)
    out = {k: np.array([s[k] for s in samples], dtype=np.int64).reshape(n) for k in
           ("seq", "frame_id", "device_us", "host_us", "lost_before", "skipped_before")}
    out["target_id"] = np.array([-1 if s["target_id"] is None else s["target_id"] for s in samples], np.int64)
    out["eyes"] = np.array([e["eye"] for e in samples[0]["eyes"]] if n else [], np.int64)
    shapes = {"pupil_flags": (), "centre": (2,), "axes": (2,), "angle_deg": (), "confidence": (),
              "glint_flags": (n_glints,), "glints": (n_glints, 2)}
    for name, tail in shapes.items():
        out[name] = np.full((n, n_eyes, *tail), 0 if "flags" in name else np.nan)
    for i, s in enumerate(samples):
        for j, e in enumerate(s["eyes"]):
            out["pupil_flags"][i, j], out["centre"][i, j], out["axes"][i, j] = e["flags"], e["centre"], e["axes"]
            out["angle_deg"][i, j], out["confidence"][i, j] = e["angle_deg"], e["confidence"]
            for k, g in enumerate(e["glints"]):
                out["glint_flags"][i, j, k], out["glints"][i, j, k] = g["flags"], (g["x"], g["y"])
    out["pupil_flags"], out["glint_flags"] = out["pupil_flags"].astype(np.uint8), out["glint_flags"].astype(np.uint8)
    return out


def read_recording(path: str | Path) -> Recording:
    """Read a recording written by `Recorder`; `RecordingError` if it is not one."""
    path = Path(path)
    header, targets, samples, end = _parse(path.read_text(encoding="utf-8").splitlines(), path)
    return Recording(header, targets, end, _arrays(samples))
