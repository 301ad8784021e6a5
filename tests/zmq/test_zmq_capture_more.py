"""Raw pyzmq scripts written from the Pupil documentation (pupil-helpers style) for what real clients need
beyond pupil data: `C` ... `c` from a single client ends in calibration.successful (the screen-marker
calibration runs by itself), Pupil Remote's first-character matching, per-topic sequence numbers, and the
limits on payload elements, annotation bytes and recording folders."""

from __future__ import annotations

import json
import time

import msgpack
import pytest
import zmq
from zmq_helpers import eventually

from eyehil.emulator.device.pupil.capture import MAX_ANNOTATION_BYTES
from eyehil.protocols.pupil import MAX_ELEMENTS

DEADLINE_S = 60.0


@pytest.fixture
def context():
    ctx = zmq.Context()
    ctx.rcvtimeo = 10_000
    ctx.linger = 0
    yield ctx
    ctx.destroy(linger=0)


def _connect(ctx: zmq.Context, port: int, *prefixes: str) -> tuple[zmq.Socket, zmq.Socket]:
    req = ctx.socket(zmq.REQ)
    req.connect(f"tcp://127.0.0.1:{port}")
    req.send_string("SUB_PORT")
    sub = ctx.socket(zmq.SUB)
    sub.connect(f"tcp://127.0.0.1:{req.recv_string()}")
    for p in prefixes:
        sub.setsockopt_string(zmq.SUBSCRIBE, p)
    _wait_subscribed(req, sub)
    return req, sub


def _wait_subscribed(req: zmq.Socket, sub: zmq.Socket) -> None:
    """Return once `sub` receives a notification sent through `req`: a ZeroMQ subscription takes effect a little
    after connecting, and a notification published before then (``notify.recording.started``) is lost to it.
    What `sub` received before the probe came back is dropped."""
    probe = "notify.eyehil_test.subscribed"
    sub.setsockopt_string(zmq.SUBSCRIBE, probe)
    end = time.monotonic() + DEADLINE_S
    while time.monotonic() < end:
        req.send_multipart([probe.encode(), msgpack.packb({"subject": probe.removeprefix("notify.")})])
        assert req.recv_string() == "Message forwarded."
        resend = time.monotonic() + 0.05  # streamed datums may keep arriving: send the probe again after 50 ms
        while time.monotonic() < resend and sub.poll(50):
            if sub.recv_multipart()[0].decode() == probe:
                sub.setsockopt_string(zmq.UNSUBSCRIBE, probe)
                return
    raise AssertionError(f"the subscription never received {probe} within {DEADLINE_S} s")


def _ask(req: zmq.Socket, command: str) -> str:
    req.send_string(command)
    return req.recv_string()


def _next(sub: zmq.Socket, topic_prefix: str, deadline_s: float = DEADLINE_S) -> dict:
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        frames = sub.recv_multipart()
        if frames[0].decode().startswith(topic_prefix):
            return msgpack.unpackb(frames[1], raw=False)
    raise AssertionError(f"no {topic_prefix} within {deadline_s} s")


def test_start_then_stop_from_one_client_ends_in_calibration_successful(server, context) -> None:
    srv = server(scene="guestrin2006")
    req, sub = _connect(context, srv.port, "notify.calibration.", "pupil.0.2d")
    _next(sub, "pupil.0.2d")  # subscribed
    assert _ask(req, "C") == "OK"
    assert _next(sub, "notify.calibration.started")
    end = time.monotonic() + DEADLINE_S  # the markers run through and the calibration stops by itself
    while True:
        outcome = _next(sub, "notify.calibration.")
        if outcome["subject"] in ("calibration.successful", "calibration.failed"):
            break
        assert time.monotonic() < end
    assert outcome["subject"] == "calibration.successful", outcome.get("reason")
    result = _next(sub, "notify.calibration.result.v2")
    assert result["params"]["n_targets"] >= 6
    _next(sub, "notify.calibration.stopped")
    assert _ask(req, "c") == "OK"  # as pupil-helpers send it; nothing left to stop


def test_remote_matches_the_first_character_as_pupil_capture(server, context) -> None:
    srv = server()
    req, _sub = _connect(context, srv.port)
    assert _ask(req, "recording stop") == "OK" and _ask(req, "version") == "3.6.0"
    assert float(_ask(req, "time please")) > 0
    assert _ask(req, "T abc") == "'abc' cannot be converted to float."
    assert _ask(req, "Calibrate") == "Unknown command."  # C and c must be the whole request
    assert _ask(req, "") == "Unknown command."


def test_datums_carry_a_per_topic_sequence_number(server, context) -> None:
    srv = server(rate_hz=200)
    _req, sub = _connect(context, srv.port, "pupil.0.2d", "glint.0")
    seqs: dict[str, list[int]] = {"pupil.0.2d": [], "glint.0": []}
    while min(len(v) for v in seqs.values()) < 100:
        frames = sub.recv_multipart()
        seqs[frames[0].decode()].append(msgpack.unpackb(frames[1], raw=False)["seq"])
    for values in seqs.values():
        assert values == list(range(values[0], values[0] + len(values)))  # nothing dropped on the loopback


def test_a_payload_of_millions_of_empty_arrays_is_refused_quickly(server, context) -> None:
    srv = server()
    req, _sub = _connect(context, srv.port)
    # ~2 MB: four arrays of MAX_ELEMENTS / 2 empty arrays each, every array within max_array_len
    bomb = msgpack.packb({"subject": "x", "a": [[[]] * (MAX_ELEMENTS // 2)] * 4})
    req.send_multipart([b"notify.x", bomb])
    reply = req.recv_string()  # within the client context's receive timeout; the parser's CPU time: bench fuzz
    assert reply.startswith("Malformed message:") and "elements" in reply  # refused at the element bound
    assert _ask(req, "v") == "3.6.0"


def test_annotations_are_bounded_in_bytes_and_recordings_stay_in_record_dir(server, context, tmp_path) -> None:
    record_dir = tmp_path / "rec"
    srv = server(record_dir=str(record_dir))
    req, sub = _connect(context, srv.port, "notify.recording.")
    big = {"topic": "annotation", "label": "x" * (MAX_ANNOTATION_BYTES + 10), "timestamp": 1.0, "duration": 0.0}
    small = {"topic": "annotation", "label": "ok", "timestamp": 2.0, "duration": 0.0}
    assert _ask(req, "R ../../escaped") == "OK"
    started = _next(sub, "notify.recording.started")
    for payload in (big, small):
        req.send_multipart([b"annotation", msgpack.packb(payload)])
        assert req.recv_string() == "Message forwarded."
    eventually(srv, lambda: srv.counters["annotations"] == 1 and srv.counters["annotations_refused"] == 1)
    assert _ask(req, "r") == "OK"
    _next(sub, "notify.recording.stopped")
    folder = record_dir / started["session_name"]
    assert started["rec_path"] == str(folder) and folder.parent == record_dir
    assert not (tmp_path / "escaped").exists() and list(tmp_path.iterdir()) == [record_dir]
    info = json.loads((folder / "info.player.json").read_text())
    assert info["recording_software_name"] == "eyehil" and info["duration_s"] > 0
    lines = (folder / "annotations.jsonl").read_text().splitlines()
    assert [json.loads(line)["label"] for line in lines] == ["ok"]


GAZE_3D_BINOCULAR = {"topic", "norm_pos", "confidence", "timestamp", "base_data", "eye_centers_3d", "gaze_normals_3d",
                     "gaze_point_3d"}  # Pupil's 3-D binocular gazer output (pupil-labs/pupil gazer_3d)
GAZE_3D_MONOCULAR = {"topic", "norm_pos", "confidence", "timestamp", "base_data", "eye_center_3d", "gaze_normal_3d",
                     "gaze_point_3d"}
PUPIL_3D = {"topic", "id", "method", "timestamp", "norm_pos", "diameter", "confidence", "ellipse", "sphere",
            "projected_sphere", "circle_3d", "diameter_3d", "model_confidence", "theta", "phi", "location"}


@pytest.mark.parametrize(("sides", "topic", "keys"), [("both", "gaze.3d.01.", GAZE_3D_BINOCULAR),
                                                       ("right", "gaze.3d.0.", GAZE_3D_MONOCULAR)])
def test_gaze_3d_and_surface_after_a_screen_marker_calibration(server, context, sides, topic, keys) -> None:
    srv = server(scene="guestrin2006", sides=sides, surface_name="monitor")
    req, sub = _connect(context, srv.port, "notify.calibration.successful", "gaze.3d.", "pupil.0.3d",
                        "surfaces.monitor")
    pupil = _next(sub, "pupil.0.3d")
    assert set(pupil) - {"seq"} == PUPIL_3D and pupil["confidence"] == 1.0
    assert 3.0 < pupil["diameter_3d"] < 8.0 and 9.0 < pupil["sphere"]["radius"] < 12.0
    assert abs(sum(v * v for v in pupil["circle_3d"]["normal"]) - 1.0) < 1e-6
    assert _ask(req, "C") == "OK"
    _next(sub, "notify.calibration.successful")
    gaze = _next(sub, topic)
    assert set(gaze) - {"seq"} == keys
    assert all(p["topic"].endswith(".3d") for p in gaze["base_data"])
    surface = _next(sub, "surfaces.monitor")
    assert surface["name"] == "monitor" and surface["gaze_on_surfaces"]
    on = surface["gaze_on_surfaces"][-1]
    assert on["topic"].startswith("gaze.3d.") and on["on_surf"] and len(on["base_data"]) == 2
    # the gaze point lies on the screen plane, where the normals from the eye centres point
    z_screen = srv.subject.solver.scene.screen.centre[2]
    assert gaze["gaze_point_3d"][2] == pytest.approx(z_screen)
