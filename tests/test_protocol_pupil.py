"""The Pupil Core Network API codecs: message frames, requests, datums, and malformed input."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from eyehil.protocols.pupil import (
    FRAME_FORMATS,
    MAX_REF_DATA,
    REPLY_FORWARDED,
    REPLY_OK,
    REPLY_TIMESYNC,
    REPLY_UNKNOWN,
    PupilMessageError,
    RefDatum,
    frame_datum,
    gaze_datum,
    glint_entry,
    norm_pos_of,
    notification,
    pack,
    parse_ref_data,
    parse_request,
    plain,
    pupil_datum,
    unpack,
)


def test_message_round_trip_with_raw_frames() -> None:
    payload = frame_datum(0, 7, 12.5, 4, 2, "gray", bytes(range(8)))
    frames = pack(payload)
    assert frames[0] == b"frame.eye.0" and frames[2] == bytes(range(8)) and len(frames) == 3
    topic, back = unpack(frames)
    assert topic == "frame.eye.0" and back["__raw_data__"] == [bytes(range(8))]
    assert back["width"] * back["height"] == len(back["__raw_data__"][0])
    assert "__raw_data__" not in msgpack.unpackb(frames[1])  # not packed into the payload


def test_pack_refuses_non_string_keys_before_any_frame() -> None:
    with pytest.raises(PupilMessageError, match="not a string"):
        pack({"topic": "x", "nested": {1: "a"}})
    with pytest.raises(PupilMessageError, match="topic"):
        pack({"subject": "x"})
    with pytest.raises(PupilMessageError, match="cannot be packed"):
        pack({"topic": "x", "thing": object()})


def _nested(depth: int) -> list:
    value: list = []
    for _ in range(depth):
        value = [value]
    return value


@pytest.mark.parametrize("frames", [
    [b"\xff\xfe", msgpack.packb({"topic": "x"})],  # topic not UTF-8
    [b"x", b"\xc1"],  # never-used msgpack byte
    [b"x", msgpack.packb({1: 2})],  # integer key
    [b"x", msgpack.packb([1, 2])],  # not a map
    [b"x", b"\x91" * 100_000],  # deeply nested
    [b"x"],  # no payload
    [b"x", msgpack.packb({"a": _nested(40)})],  # nested deeper than the limit
])
def test_unpack_refuses_malformed_messages(frames) -> None:
    with pytest.raises(PupilMessageError):
        unpack(frames)


@pytest.mark.parametrize(("frames", "kind", "argument"), [
    ([b"SUB_PORT"], "sub_port", None), ([b"PUB_PORT"], "pub_port", None), ([b"R"], "record_start", None),
    ([b"R session 1"], "record_start", "session 1"), ([b"r"], "record_stop", None),
    ([b"C"], "calibration_start", None), ([b"c"], "calibration_stop", None), ([b"T 12.5"], "time_sync", 12.5),
    ([b"t"], "time_query", None), ([b"v"], "version", None), ([b"hello"], "unknown", "hello"),
    ([b"T abc"], "unknown", "T abc"), ([b"\xff"], "invalid", "request is not UTF-8"),
])
def test_request_parsing(frames, kind: str, argument) -> None:
    r = parse_request(frames)
    assert (r.kind, r.argument) == (kind, argument)


def test_multipart_request_is_forwarded_whatever_its_first_frame() -> None:
    frames = [b"SUB_PORT", msgpack.packb({"topic": "SUB_PORT"})]
    assert parse_request(frames).kind == "forward"


def test_datums_follow_pupil_conventions() -> None:
    d = pupil_datum(1, 3.0, (160.0, 60.0), (40.0, 30.0), 12.0, 0.99, (320, 240), [{"center": [150.0, 70.0], "led": 0}])
    assert d["topic"] == "pupil.1.2d" and d["method"] == "2d c++" and d["id"] == 1
    assert d["norm_pos"] == [0.5, 0.75] and d["diameter"] == 40.0
    assert d["ellipse"] == {"center": [160.0, 60.0], "axes": [40.0, 30.0], "angle": 12.0}
    assert notification("calibration.started") == {"subject": "calibration.started",
                                                   "topic": "notify.calibration.started"}
    assert gaze_datum([1, 0], 1.0, (0.5, 0.5), 1.0, [])["topic"] == "gaze.2d.01."
    with pytest.raises(PupilMessageError, match="format"):
        frame_datum(0, 0, 0.0, 1, 1, "png", b"x")


@pytest.mark.parametrize("text", [b"T nan", b"T inf", b"T -inf", b"T ", b"T 1e999"])
def test_time_sync_needs_a_finite_float(text: bytes) -> None:
    assert parse_request([text]).kind == "unknown"


def test_reference_data_parsing() -> None:
    payload = {"ref_data": [{"norm_pos": [0.5, 0.25], "timestamp": 2.0}, {"norm_pos": (0, 1), "timestamp": 1},
                            {"norm_pos": [0.5], "timestamp": 1.0}, {"norm_pos": [True, 0.5], "timestamp": 1.0},
                            {"norm_pos": [0.1, float("nan")], "timestamp": 1.0},
                            {"norm_pos": [0.1, 0.2], "timestamp": "now"}, "junk", {"timestamp": 3.0}]}
    refs, refused = parse_ref_data(payload)
    assert refs == [RefDatum((0.0, 1.0), 1.0), RefDatum((0.5, 0.25), 2.0)] and refused == 6
    assert parse_ref_data({"ref_data": "x"}) == ([], 1)
    assert parse_ref_data({"ref_data": [{"norm_pos": [0, 0], "timestamp": 0}] * (MAX_REF_DATA + 5)})[1] == 5
    assert norm_pos_of({"norm_pos": [1, 2]}) == (1.0, 2.0) and norm_pos_of({"norm_pos": "x"}) is None


def test_plain_makes_parameters_packable() -> None:
    value = plain({"a": np.arange(3), "b": (np.float64(1.5), {"c": np.bool_(True)}), 3: None, "d": object})
    assert value["a"] == [0, 1, 2] and value["b"] == [1.5, {"c": True}] and value["3"] is None
    assert isinstance(value["d"], str)
    assert unpack(pack({"topic": "x", "params": value}))[1]["params"]["a"] == [0, 1, 2]


def test_glint_entries_and_replies() -> None:
    assert glint_entry(1, np.array([1.5, 2.0]), np.True_) == {"center": [1.5, 2.0], "led": 1, "valid": True}
    assert (REPLY_FORWARDED, REPLY_TIMESYNC, REPLY_UNKNOWN, REPLY_OK) == (
        "Message forwarded.", "Timesync successful.", "Unknown command.", "OK")
    assert FRAME_FORMATS == ("gray", "bgr", "jpeg")
