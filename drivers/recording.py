"""Recordings: samples with device and host timestamps, the configuration and target labels, in JSON Lines.

Format (docs/recording.md): UTF-8, one JSON object per line; the first line is the header, then
"target" and "sample" records in arrival order, then one "end" record. A file cut short (the host
crashed) lacks the end record and may end with a partial line: `read_recording` keeps every complete
record and reports ``complete=False``. Whatever the file holds, the reader raises only `RecordingError`
(`eyehil.drivers.errors`): every record is checked against the format before use (types, integer ranges,
finite numbers, nesting); lines longer than `MAX_LINE` characters are refused.

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

from eyehil.drivers.errors import RecordingError
from eyehil.drivers.wire import Sample, host_now_us
from eyehil.protocols.replies import Status

FORMAT = "eyehil-recording"
VERSION = 1
MAX_LINE = 1 << 20  # characters in one record
MAX_EYES, MAX_GLINTS = 2, 8
_I64 = 1 << 63

__all__ = ["FORMAT", "VERSION", "Recorder", "Recording", "RecordingError", "parse_recording_bytes", "read_recording"]


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


def _parse(lines: list[str], path: str | Path) -> tuple[dict, list[dict], list[dict], dict | None]:
    """Header, targets, samples, end; a broken LAST line is tolerated (a cut-short file)."""
    records = []
    for number, line in enumerate(lines, 1):
        try:
            if len(line) > MAX_LINE:
                raise ValueError(f"line longer than {MAX_LINE} characters")
            record = json.loads(line)
            if not isinstance(record, dict):
                raise ValueError("a record must be a JSON object")
            records.append(record)
        except (ValueError, RecursionError) as exc:
            if number == len(lines):
                break
            raise RecordingError(f"{path}:{number}: not a JSON record: {exc}") from None
    if not records or records[0].get("format") != FORMAT or records[0].get("version") != VERSION:
        raise RecordingError(f"{path}: not an {FORMAT} version {VERSION} file")
    kinds: dict[str, list] = {"target": [], "sample": [], "end": []}
    for number, record in enumerate(records[1:], 2):
        kind = record.get("type")
        if not isinstance(kind, str) or kind not in kinds:
            raise RecordingError(f"{path}:{number}: unknown record type {str(kind)[:40]!r}")
        if kind == "sample":
            _check_sample(record, f"{path}:{number}")
        elif kind == "end" and not isinstance(record.get("stats", {}), dict):
            raise RecordingError(f"{path}:{number}: end.stats must be an object")
        kinds[kind].append(record)
    return records[0], kinds["target"], kinds["sample"], (kinds["end"] or [None])[-1]


def _int(value: Any, where: str, lo: int = -_I64, hi: int = _I64 - 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise RecordingError(f"{where}: expected an integer in [{lo}, {hi}], got {str(value)[:40]}")
    return value


def _num(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not abs(value) < 1e300:
        raise RecordingError(f"{where}: expected a finite number, got {str(value)[:40]}")
    return float(value)


def _pair(value: Any, where: str) -> None:
    if not isinstance(value, list) or len(value) != 2:
        raise RecordingError(f"{where}: expected two numbers")
    for v in value:
        _num(v, where)


def _check_sample(s: dict, where: str) -> None:
    """Raise `RecordingError` unless `s` is a sample record `_arrays` can take."""
    for key in ("seq", "frame_id", "device_us", "host_us", "lost_before", "skipped_before"):
        _int(s.get(key), f"{where}: {key}")
    if "target_id" not in s:
        raise RecordingError(f"{where}: target_id missing (null for none)")
    if s["target_id"] is not None:
        _int(s["target_id"], f"{where}: target_id")
    eyes = s.get("eyes")
    if not isinstance(eyes, list) or len(eyes) > MAX_EYES:
        raise RecordingError(f"{where}: eyes must be a list of at most {MAX_EYES} records")
    for e in eyes:
        if not isinstance(e, dict):
            raise RecordingError(f"{where}: an eye record must be an object")
        _int(e.get("eye"), f"{where}: eye", 0, 1)
        _int(e.get("flags"), f"{where}: flags", 0, 255)
        _pair(e.get("centre"), f"{where}: centre")
        _pair(e.get("axes"), f"{where}: axes")
        _num(e.get("angle_deg"), f"{where}: angle_deg")
        _num(e.get("confidence"), f"{where}: confidence")
        glints = e.get("glints")
        if not isinstance(glints, list) or len(glints) > MAX_GLINTS:
            raise RecordingError(f"{where}: glints must be a list of at most {MAX_GLINTS} records")
        for g in glints:
            if not isinstance(g, dict):
                raise RecordingError(f"{where}: a glint record must be an object")
            _int(g.get("flags"), f"{where}: glint flags", 0, 255)
            _num(g.get("x"), f"{where}: glint x")
            _num(g.get("y"), f"{where}: glint y")


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
    return parse_recording_bytes(path.read_bytes(), path)


def parse_recording_bytes(raw: bytes, origin: str | Path = "recording") -> Recording:
    """A recording from the bytes of its file (`origin` names it in errors); `RecordingError` if it is not one."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{origin}: not UTF-8 ({exc.reason} at byte {exc.start})") from None
    header, targets, samples, end = _parse(text.splitlines(), origin)
    return Recording(header, targets, end, _arrays(samples))
