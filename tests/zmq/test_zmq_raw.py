"""A raw pyzmq client doing what the pupil-helpers scripts do (filter_messages.py, recv_world_video_frames.py,
pupil_remote_control.py): its own context, SUB_PORT, prefix subscriptions, notifications without a `topic`
key, bgr frames reshaped; and `eyehil emulate --link zmq` from the command line."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time

import msgpack
import numpy as np
import pytest
import zmq
from pupil_labs.pupil_core_network_client import Device


@pytest.fixture
def context():
    ctx = zmq.Context()
    ctx.rcvtimeo = 10_000
    ctx.linger = 0
    yield ctx
    ctx.destroy(linger=0)


def _req(ctx: zmq.Context, port: int) -> zmq.Socket:
    req = ctx.socket(zmq.REQ)
    req.connect(f"tcp://127.0.0.1:{port}")
    return req


def _ask(req: zmq.Socket, command: str) -> str:
    req.send_string(command)
    return req.recv_string()


def _notify(req: zmq.Socket, notification: dict) -> str:
    """pupil-helpers' notify(): topic frame, then the payload (which has no `topic` key)."""
    req.send_string("notify." + notification["subject"], flags=zmq.SNDMORE)
    req.send(msgpack.packb(notification, use_bin_type=True))
    return req.recv_string()


def _recv(sub: zmq.Socket) -> tuple[str, dict]:
    topic = sub.recv_string()
    payload = msgpack.loads(sub.recv(), raw=False)
    extra = []
    while sub.get(zmq.RCVMORE):
        extra.append(sub.recv())
    if extra:
        payload["__raw_data__"] = extra
    return topic, payload


def test_pupil_remote_commands(server, context) -> None:
    srv = server()
    req = _req(context, srv.port)
    replies = {c: _ask(req, c) for c in ("SUB_PORT", "PUB_PORT", "R", "r", "C", "c", "v", "T 5.0", "t", "xyz")}
    assert replies["SUB_PORT"] == str(srv.sub_port) and replies["PUB_PORT"] == str(srv.pub_port)
    assert replies["R"] == replies["r"] == replies["C"] == replies["c"] == "OK"
    assert replies["v"] == "3.6.0" and replies["T 5.0"] == "Timesync successful."
    assert replies["xyz"] == "Unknown command."
    assert 5.0 <= float(replies["t"]) < 6.0
    assert _ask(req, "R my session") == "OK"


def test_prefix_subscriptions_and_bgr_frames(server, context) -> None:
    srv = server(scene="guestrin2006", frame_rate_hz=50)
    req = _req(context, srv.port)
    sub_port = _ask(req, "SUB_PORT")
    assert _notify(req, {"subject": "start_plugin", "name": "Frame_Publisher", "args": {"format": "bgr"}}) \
        == "Message forwarded."
    sub = context.socket(zmq.SUB)
    sub.connect(f"tcp://127.0.0.1:{sub_port}")
    sub.setsockopt_string(zmq.SUBSCRIBE, "frame.")
    sub.setsockopt_string(zmq.SUBSCRIBE, "pupil.")
    topics, image = set(), None
    deadline = time.monotonic() + 10
    while image is None and time.monotonic() < deadline:
        topic, msg = _recv(sub)
        topics.add(topic)
        if topic == "frame.eye.0" and msg["format"] == "bgr":
            image = np.frombuffer(msg["__raw_data__"][0], dtype=np.uint8).reshape(msg["height"], msg["width"], 3)
    assert image is not None and image.shape == (240, 320, 3)
    assert (image[..., 0] == image[..., 2]).all() and image.min() < 60 < image.max()
    assert topics <= {"frame.eye.0", "frame.world", "pupil.0.2d", "pupil.0.3d"} and "pupil.0.2d" in topics


def test_publishing_directly_to_the_backbone(server, context) -> None:
    srv = server()
    req = _req(context, srv.port)
    pub = context.socket(zmq.PUB)
    pub.connect(f"tcp://127.0.0.1:{_ask(req, 'PUB_PORT')}")
    sub = context.socket(zmq.SUB)
    sub.connect(f"tcp://127.0.0.1:{_ask(req, 'SUB_PORT')}")
    sub.setsockopt_string(zmq.SUBSCRIBE, "notify.frame_publishing.started")
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:  # the PUB and the SUB connect asynchronously: repeat until heard
        pub.send_multipart([b"notify.frame_publishing.set_format",
                            msgpack.packb({"subject": "frame_publishing.set_format", "format": "jpeg",
                                           "topic": "notify.frame_publishing.set_format"})])
        if sub.poll(50):
            break
    assert _recv(sub)[1]["format"] == "jpeg"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_command_line_emulator() -> None:
    port = _free_port()
    cmd = [sys.executable, "-m", "eyehil.cli", "emulate", "--link", "zmq", "--port", str(port), "--duration", "60"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == f"url: tcp://127.0.0.1:{port}"
        device = Device("127.0.0.1", port)
        assert device.request_version() == "3.6.0"
        device.disconnect()
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
