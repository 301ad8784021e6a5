"""The Pupil Core Network API (ZeroMQ), as pure codecs: no sockets, no threads.

Wire format (pupil-labs/pupil `zmq_tools.py`): a message is the multipart
``[topic (UTF-8), msgpack(payload, use_bin_type=True), *raw_frames]``; the payload holds `topic`, every
map key is a string (receivers unpack with ``strict_map_key=True``), and a payload key
``__raw_data__`` (a list of buffers) is removed before packing and sent as the extra frames. Payloads
are serialised before the first frame is sent, so a payload that cannot be packed leaves no dangling
frame.

Pupil Remote (REQ/REP) requests, checked in this order: any multipart message (forwarded to the
backbone, reply ``Message forwarded.``), ``SUB_PORT``, ``PUB_PORT``, then by the first character as
Pupil Capture does: ``R[ name]``, ``r``, ``C`` and ``c`` (whole request), ``T <float>``, ``t``, ``v``,
anything else (``Unknown command.``). The replies are the constants
``REPLY_*``; a request that is not UTF-8 gets ``Unknown command.``; a multipart request that fails `unpack`
gets ``Malformed message: <reason>`` and is not forwarded (Pupil Capture would forward it blindly).

Datums (image pixels with the origin at the top-left; Pupil's eye ids: 0 right, 1 left):
``pupil.<id>.2d`` {topic, id, method "2d c++", norm_pos (x / w, 1 - y / h), diameter (px, the major
axis), confidence, timestamp (s, device clock), ellipse {center, axes (full lengths), angle (deg)},
glints (our extra key)}; ``glint.<id>``; ``frame.eye.<id>`` and ``frame.world`` {topic, width, height,
index, timestamp, format} + one raw frame; notifications ``notify.<subject>`` {subject, topic, ...}; gaze
``gaze.2d.<eyes>.`` (note the trailing dot) {topic, norm_pos (on the screen), confidence, timestamp,
base_data}.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import msgpack

#: Limits on what a receiver accepts from the network (bytes, nesting depth, elements: the items of every
#: array and map plus the containers themselves, counted while unpacking, so that a small payload of millions
#: of empty arrays is refused after MAX_ELEMENTS of them instead of costing hundreds of MB).
MAX_PAYLOAD_BYTES = 16 * 1024 * 1024
MAX_DEPTH = 32
MAX_ELEMENTS = 1_000_000
VERSION = "3.6.0"

RAW = "__raw_data__"
FRAME_FORMATS = ("gray", "bgr", "jpeg")
#: At most this many reference data per `calibration.add_ref_data` notification.
MAX_REF_DATA = 100_000

REPLY_FORWARDED = "Message forwarded."
REPLY_OK = "OK"
REPLY_TIMESYNC = "Timesync successful."
REPLY_UNKNOWN = "Unknown command."
REPLY_MALFORMED = "Malformed message: "


class PupilMessageError(ValueError):
    """A message that cannot be packed or unpacked (the reason is the message)."""


_SCALARS = frozenset({str, int, float, bool, bytes, type(None)})


def _check_keys(value: Any, depth: int = 0) -> None:
    """PupilMessageError unless every map key in `value` is a string and containers nest at most `MAX_DEPTH`.

    Exact dicts, lists and tuples are tested by type first: the Mapping ABC check is slow, and the facade packs
    about 3,000 datums a second."""
    if depth > MAX_DEPTH:
        raise PupilMessageError(f"payload nested deeper than {MAX_DEPTH} levels")
    kind = type(value)
    if kind is list or kind is tuple:
        items = value
    elif kind is dict or isinstance(value, Mapping):
        for key in value:
            if not isinstance(key, str):
                raise PupilMessageError(f"payload map key {key!r} is not a string")
        items = value.values()
    elif isinstance(value, list | tuple):
        items = value
    else:
        return
    for item in items:
        if type(item) not in _SCALARS:
            _check_keys(item, depth + 1)


def pack(payload: Mapping[str, Any], check_keys: bool = True) -> list[bytes]:
    """The frames of one message: topic, msgpack payload, then the raw frames of `__raw_data__`.

    `check_keys` False skips the walk through the payload that proves every map key a string (`_check_keys`):
    for datums a device builds itself from literal keys, at a kilohertz (tests/zmq check that they pass it)."""
    if "topic" not in payload or not isinstance(payload["topic"], str):
        raise PupilMessageError("a payload needs a string 'topic'")
    body = {k: v for k, v in payload.items() if k != RAW}
    if check_keys:
        _check_keys(body)
    try:
        packed = msgpack.packb(body, use_bin_type=True)
    except (TypeError, ValueError, OverflowError) as exc:
        raise PupilMessageError(f"payload cannot be packed: {exc}") from exc
    raw = [b if type(b) is bytes else bytes(memoryview(b)) for b in payload.get(RAW, ())]  # bytes: no copy
    return [body["topic"].encode("utf-8"), packed, *raw]


def unpack(frames: Sequence[bytes]) -> tuple[str, dict[str, Any]]:
    """(topic, payload) of a received multipart message; extra frames go to payload['__raw_data__']."""
    if len(frames) < 2:
        raise PupilMessageError("a message needs at least a topic frame and a payload frame")
    try:
        topic = bytes(frames[0]).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PupilMessageError("topic is not UTF-8") from exc
    if len(frames[1]) > MAX_PAYLOAD_BYTES:
        raise PupilMessageError(f"payload of {len(frames[1])} bytes exceeds {MAX_PAYLOAD_BYTES}")
    count = [0]

    def counted(container: Any) -> Any:
        count[0] += len(container) + 1
        if count[0] > MAX_ELEMENTS:
            raise PupilMessageError(f"payload has more than {MAX_ELEMENTS} elements")
        return container

    try:
        payload = msgpack.unpackb(bytes(frames[1]), raw=False, strict_map_key=True, list_hook=counted,
                                  object_hook=counted, max_array_len=MAX_ELEMENTS, max_map_len=MAX_ELEMENTS)
    except PupilMessageError:
        raise
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError, TypeError) as exc:
        raise PupilMessageError(f"payload is not valid msgpack with string keys: {exc or type(exc).__name__}") from exc
    if not isinstance(payload, dict):
        raise PupilMessageError("payload is not a map")
    _check_keys(payload)
    if len(frames) > 2:
        payload[RAW] = [bytes(f) for f in frames[2:]]
    return topic, payload


#: the largest Pupil time (s) a client may set with ``T`` (about 317 years; Pupil time is a monotonic clock's
#: seconds, so anything larger is an error, and it keeps the device's integer microseconds far from overflow)
MAX_PUPIL_TIME_S = 1e10


@dataclass(frozen=True)
class Request:
    """A parsed Pupil Remote request: `kind` and its argument (name, float, text or frames)."""

    kind: str  # forward, sub_port, pub_port, record_start, record_stop, calibration_start,
    # calibration_stop, time_sync, time_sync_failed, time_query, version, unknown, invalid
    argument: Any = None


def parse_request(frames: Sequence[bytes]) -> Request:
    """Classify a Pupil Remote request as Pupil Capture's `pupil_remote.py` does: multipart first, then
    ``SUB_PORT`` and ``PUB_PORT`` exactly, then by the FIRST character (``R`` with the session name from the
    third character on, ``r``, ``T`` with the float from the third character, ``t``, ``v``), except ``C`` and
    ``c``, which must be the whole request. ``T`` with no finite float is `time_sync_failed` (Pupil's reply
    names the text that is no float; we also refuse nan, inf and |T| > `MAX_PUPIL_TIME_S`)."""
    if len(frames) > 1:
        return Request("forward", list(frames))
    try:
        text = bytes(frames[0]).decode("utf-8") if frames else ""
    except UnicodeDecodeError:
        return Request("invalid", "request is not UTF-8")
    exact = {"SUB_PORT": "sub_port", "PUB_PORT": "pub_port", "C": "calibration_start", "c": "calibration_stop"}
    if text in exact:
        return Request(exact[text])
    first = text[:1]
    if first == "R":
        return Request("record_start", text[2:] or None)
    if first == "T":
        try:
            value = float(text[2:])
        except ValueError:
            return Request("time_sync_failed", text[2:])
        if not (math.isfinite(value) and abs(value) <= MAX_PUPIL_TIME_S):
            return Request("time_sync_failed", text[2:])
        return Request("time_sync", value)
    plain_kinds = {"r": "record_stop", "t": "time_query", "v": "version"}
    return Request(plain_kinds[first]) if first in plain_kinds else Request("unknown", text)


def timesync_failed_reply(text: str) -> str:
    """Pupil Capture's reply to a ``T`` whose argument is no float."""
    return f"'{text}' cannot be converted to float."


def notification(subject: str, **fields: Any) -> dict[str, Any]:
    """A notification payload `notify.<subject>`."""
    return {"subject": subject, "topic": f"notify.{subject}", **fields}


def pupil_datum(eye_id: int, timestamp: float, centre: Sequence[float], axes: Sequence[float], angle_deg: float,
                confidence: float, image_size: tuple[int, int], glints: list[dict[str, Any]] | None = None
                ) -> dict[str, Any]:
    """A `pupil.<id>.2d` datum; `centre` px (top-left origin), `axes` full lengths px."""
    width, height = image_size
    x, y = float(centre[0]), float(centre[1])
    return {
        "topic": f"pupil.{eye_id}.2d", "id": eye_id, "method": "2d c++", "timestamp": float(timestamp),
        "norm_pos": [x / width, 1.0 - y / height], "diameter": float(max(axes)), "confidence": float(confidence),
        "ellipse": {"center": [x, y], "axes": [float(axes[0]), float(axes[1])], "angle": float(angle_deg)},
        "glints": glints or [],
    }


def glint_datum(eye_id: int, timestamp: float, glints: list[dict[str, Any]]) -> dict[str, Any]:
    """A `glint.<id>` datum: {center [x, y] px, led, valid} per LED."""
    return {"topic": f"glint.{eye_id}", "id": eye_id, "timestamp": float(timestamp), "glints": glints}


def frame_datum(eye_id: int | str, index: int, timestamp: float, width: int, height: int, fmt: str,
                data: bytes) -> dict[str, Any]:
    """A `frame.eye.<id>` message (`eye_id` "world": `frame.world`) with its image as the raw frame."""
    if fmt not in ("gray", "bgr", "jpeg"):
        raise PupilMessageError(f"frame format {fmt!r}: expected gray, bgr or jpeg")
    topic = "frame.world" if eye_id == "world" else f"frame.eye.{int(eye_id)}"
    return {"topic": topic, "width": int(width), "height": int(height), "index": int(index),
            "timestamp": float(timestamp), "format": fmt, RAW: [data]}


def gaze_datum(eye_ids: Sequence[int], timestamp: float, norm_pos: Sequence[float], confidence: float,
               base_data: list[dict[str, Any]]) -> dict[str, Any]:
    """A `gaze.2d.<ids>.` datum, `norm_pos` on the screen (origin bottom-left)."""
    ids = "".join(str(i) for i in sorted(eye_ids))
    return {"topic": f"gaze.2d.{ids}.", "norm_pos": [float(norm_pos[0]), float(norm_pos[1])],
            "confidence": float(confidence), "timestamp": float(timestamp), "base_data": base_data}


def glint_entry(led: int, centre: Sequence[float], valid: bool) -> dict[str, Any]:
    """One glint of a `pupil.<id>.2d` or `glint.<id>` datum: {center [x, y] px (eye image), led, valid}."""
    return {"center": [float(centre[0]), float(centre[1])], "led": int(led), "valid": bool(valid)}


@dataclass(frozen=True)
class RefDatum:
    """One calibration reference datum: where the target was (`norm_pos`, screen, origin bottom-left) when."""

    norm_pos: tuple[float, float]
    timestamp: float  # s, Pupil time


def _finite_pair(value: Any) -> tuple[float, float] | None:
    if not isinstance(value, list | tuple) or len(value) != 2:
        return None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return None
    pair = (float(value[0]), float(value[1]))
    return pair if all(math.isfinite(v) for v in pair) else None


def parse_ref_data(payload: Mapping[str, Any]) -> tuple[list[RefDatum], int]:
    """The usable entries of a `calibration.add_ref_data` payload {ref_data: [{norm_pos, timestamp}, ...]},
    sorted by time, and how many entries were refused (not a map, no finite norm_pos pair or timestamp,
    or beyond `MAX_REF_DATA`)."""
    entries = payload.get("ref_data")
    if not isinstance(entries, list):
        return [], 1
    good: list[RefDatum] = []
    for entry in entries[:MAX_REF_DATA]:
        pos = _finite_pair(entry.get("norm_pos")) if isinstance(entry, dict) else None
        ts = entry.get("timestamp") if isinstance(entry, dict) else None
        if pos is not None and isinstance(ts, int | float) and not isinstance(ts, bool) and math.isfinite(ts):
            good.append(RefDatum(pos, float(ts)))
    return sorted(good, key=lambda r: r.timestamp), len(entries) - len(good)


def norm_pos_of(payload: Mapping[str, Any]) -> tuple[float, float] | None:
    """The finite `norm_pos` pair of a payload, or None."""
    return _finite_pair(payload.get("norm_pos"))


def plain(value: Any, depth: int = 0) -> Any:
    """`value` with numpy arrays and scalars, tuples and other sequences made msgpack-ready lists and floats;
    map keys become strings (a calibration's parameters, for `calibration.result.v2`)."""
    if depth > MAX_DEPTH:
        raise PupilMessageError(f"value nested deeper than {MAX_DEPTH} levels")
    if isinstance(value, Mapping):
        return {str(k): plain(v, depth + 1) for k, v in value.items()}
    if isinstance(value, str | bytes | bool | None):
        return value
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return plain(value.tolist(), depth + 1)
    if isinstance(value, list | tuple):
        return [plain(v, depth + 1) for v in value]
    if isinstance(value, int | float):
        return value
    return str(value)
