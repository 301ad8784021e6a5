"""Conformance with the real, unmodified client `pupil-core-network-client` (PyPI, pinned in the test extra):
connect, version, time sync and clock offset, subscriptions to pupil, glint and frame topics, frame buffers,
notifications, annotations, recording, high-frequency message sending."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest
from zmq_helpers import eventually, subscribed, topic_is, wait_for

from eyehil.protocols.pupil import VERSION


def test_connect_version_and_clock_offset(server, device_of) -> None:
    srv = server()
    device = device_of(srv)  # announces itself, asks PUB_PORT, SUB_PORT, then `t` ten times
    assert device.ipc_pub_port == srv.pub_port and device.ipc_sub_port == srv.sub_port
    assert device.request_version() == VERSION
    stats = device.clock_offset_statistics
    assert stats.num_measurements == 10 and stats.std_offset < 0.01
    before = time.monotonic()
    remote = device.request_current_pupil_time()
    after = time.monotonic()
    assert before + stats.mean_offset - 0.01 <= remote <= after + stats.mean_offset + 0.01
    assert srv.counters["requests"] >= 14


def test_time_sync_sets_pupil_time(server, device_of) -> None:
    srv = server()
    device = device_of(srv)
    assert device._send_recv_command("T 1000.5") == "Timesync successful."
    now = device.request_current_pupil_time()
    assert 1000.5 <= now < 1001.5
    offset = device.estimate_client_to_remote_clock_offset().mean_offset
    assert abs(device.client_clock() + offset - device.request_current_pupil_time()) < 0.01


def test_pupil_and_glint_datums(server, device_of, subscribe) -> None:
    srv = server(scene="guestrin2006", rate_hz=250)
    device = device_of(srv)
    sub = subscribe(device, ["pupil.", "glint."])
    pupil = wait_for(sub, topic_is("pupil.0.2d")).payload
    assert pupil["method"] == "2d c++" and pupil["id"] == 0 and pupil["confidence"] == 1.0
    w, h = 320, 240
    x, y = pupil["ellipse"]["center"]
    assert 0 <= x < w and 0 <= y < h
    assert pupil["norm_pos"] == pytest.approx([x / w, 1 - y / h])
    assert pupil["diameter"] == max(pupil["ellipse"]["axes"]) > 10
    assert [g["led"] for g in pupil["glints"]] == [0, 1] and all(g["valid"] for g in pupil["glints"])
    assert abs(pupil["timestamp"] - device.current_pupil_time()) < 0.5
    glint = wait_for(sub, topic_is("glint.0")).payload
    assert len(glint["glints"]) == 2


@pytest.mark.parametrize("fmt", ["gray", "bgr", "jpeg"])
def test_frames_in_each_format(server, device_of, subscribe, fmt: str) -> None:
    srv = server(scene="blignaut2014", frame_rate_hz=50)
    device = device_of(srv)
    sub = subscribe(device, ["frame.eye.", "notify.frame_publishing"])
    subscribed_to_frames = wait_for(sub, lambda m: m.topic.startswith("frame.eye."))
    assert subscribed_to_frames.payload["format"] == "gray"
    assert device.send_notification({"subject": "frame_publishing.set_format", "format": fmt}) == "Message forwarded."
    assert wait_for(sub, topic_is("notify.frame_publishing.started")).payload["format"] == fmt
    seen = {}
    while len(seen) < 2:
        m = wait_for(sub, lambda m: m.topic.startswith("frame.eye.") and m.payload["format"] == fmt)
        seen[m.topic] = m
    for eye_id in (0, 1):
        payload, raw = seen[f"frame.eye.{eye_id}"].payload, seen[f"frame.eye.{eye_id}"].raw_data
        w, h = payload["width"], payload["height"]
        assert (w, h) == (320, 240) and len(raw) == 1
        if fmt == "gray":
            assert len(raw[0]) == w * h
        elif fmt == "bgr":
            assert len(raw[0]) == w * h * 3
        else:
            image = cv2.imdecode(np.frombuffer(raw[0], np.uint8), cv2.IMREAD_GRAYSCALE)
            assert image.shape == (h, w) and image.min() < 60 < image.max()  # a dark pupil on lighter skin


def test_frame_indices_count_up(server, device_of, subscribe) -> None:
    srv = server(frame_rate_hz=50)
    sub = subscribe(device_of(srv), ["frame.eye.0"])
    first = wait_for(sub, topic_is("frame.eye.0")).payload
    second = wait_for(sub, topic_is("frame.eye.0")).payload
    assert second["index"] > first["index"] and second["timestamp"] > first["timestamp"]


def test_notifications_annotations_and_recording(server, device_of, subscribe, tmp_path) -> None:
    srv = server(record_dir=str(tmp_path))
    device = device_of(srv)
    sub = subscribe(device, ["notify.", "annotation"])
    subscribed(device, sub)
    assert device.request_recording_start("session 1") == "OK"
    started = wait_for(sub, topic_is("notify.recording.started")).payload
    assert started["session_name"] == "session_1"
    assert device.send_annotation("trial", duration=0.5, extra={"k": [1, 2]}) == "Message forwarded."
    annotation = wait_for(sub, topic_is("annotation")).payload
    assert annotation["label"] == "trial" and annotation["duration"] == 0.5
    assert device.request_recording_stop() == "OK"
    wait_for(sub, topic_is("notify.recording.stopped"))
    recorded = [a for a in srv.annotations if a["label"] == "trial"]
    assert recorded and recorded[0]["recording"] == "session_1" and recorded[0]["extra"] == {"k": [1, 2]}
    assert "trial" in (tmp_path / "session_1" / "annotations.jsonl").read_text()


def test_high_frequency_message_sending(server, device_of, subscribe) -> None:
    srv = server()
    device = device_of(srv)
    sub = subscribe(device, ["annotation"])
    with device.high_frequency_message_sending():
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:  # the client's PUB connects asynchronously: send until one arrives
            assert device.send_annotation("hf") == "OK"
            if sub.recv_new_message(timeout_ms=50) is not None:
                break
        for i in range(500):
            device.send_annotation("burst", index=i)
        last = wait_for(sub, lambda m: m.payload.get("index") == 499)
    assert last.payload["label"] == "burst"
    eventually(lambda: sum(a["label"] == "burst" for a in srv.annotations) == 500)


@pytest.mark.parametrize("kind", ["process", "thread"])
def test_frames_rendered_by_workers_arrive_in_order(server, device_of, subscribe, kind: str) -> None:
    """Images rendered and encoded in a render pool (issue 16) are published in exposure order."""
    srv = server(scene="blignaut2014", frame_rate_hz=50, render_workers=1, render_kind=kind, frame_format="jpeg")
    sub = subscribe(device_of(srv), ["frame.eye.1"])
    messages = [wait_for(sub, topic_is("frame.eye.1"), timeout_s=60) for _ in range(4)]
    indices = [m.payload["index"] for m in messages]
    assert indices == sorted(indices) and len(set(indices)) == 4
    image = cv2.imdecode(np.frombuffer(messages[-1].raw_data[0], np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image.shape == (240, 320) and image.min() < 60 < image.max()
    assert srv.counters["frames_published"] >= 4
