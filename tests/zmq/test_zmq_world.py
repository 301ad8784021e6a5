"""`frame.world`: the world view's geometry and drawing (known answers), the target it shows, and the frames
as the real client `pupil-core-network-client` and a raw pyzmq script (as pupil-helpers'
recv_world_video_frames.py) receive them after `start_plugin Frame_Publisher {format}`."""

from __future__ import annotations

import cv2
import msgpack
import numpy as np
import pytest
import zmq
from zmq_helpers import eventually, subscribed, topic_is, wait_for

from eyehil.emulator.device.gaze import Fixation, Pursuit, Saccade, Timeline, plan
from eyehil.emulator.device.pupil.world import (
    MARKER_MM,
    SCREEN_GRAY,
    TargetTrack,
    WorldView,
    render_world,
    script_target,
)

GUESTRIN_SCREEN_MM = (377.0, 301.0)


def _marker_centre(image: np.ndarray) -> tuple[float, float]:
    """Centroid (px) of the marker's black pixels (its outer ring and centre dot, symmetric about its centre)."""
    ys, xs = np.nonzero(image < SCREEN_GRAY // 2)
    assert len(xs) > 20, "no marker in the image"
    return float(xs.mean()), float(ys.mean())


def _norm_of(view_size: tuple[int, int], px: tuple[float, float]) -> tuple[float, float]:
    w, h = view_size
    return (px[0] + 0.5) / w, 1.0 - (px[1] + 0.5) / h


def _decode(payload: dict, raw: bytes) -> np.ndarray:
    w, h, fmt = payload["width"], payload["height"], payload["format"]
    if fmt == "gray":
        return np.frombuffer(raw, np.uint8).reshape(h, w)
    if fmt == "bgr":
        bgr = np.frombuffer(raw, np.uint8).reshape(h, w, 3)
        assert (bgr[..., 0] == bgr[..., 2]).all()
        return bgr[..., 1]
    image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image.shape == (h, w)
    return image


# --- geometry and drawing ------------------------------------------------------------------------------
def test_world_view_known_answers() -> None:
    view = WorldView.of_screen(GUESTRIN_SCREEN_MM)
    assert view.size == (640, 510)  # 640 * 301 / 377 = 510.98 -> the nearest even 510
    assert np.allclose(view.pixel_of(np.zeros(2)), (319.5, 254.5))
    # norm (0, 1), the top-left corner as the subject sees it, is scene mm (+188.5, +150.5): pixel (-0.5, -0.5)
    assert np.allclose(view.pixel_of(np.array([188.5, 150.5])), (-0.5, -0.5))
    assert np.allclose(view.pixel_of(np.array([-188.5, -150.5])), (639.5, 509.5))
    with pytest.raises(ValueError):
        WorldView.of_screen(GUESTRIN_SCREEN_MM, 8)


def test_render_world_draws_the_marker_where_the_target_is() -> None:
    view = WorldView.of_screen(GUESTRIN_SCREEN_MM, 800)
    target = (-100.0, 60.0)  # mm: right of the centre as the subject sees it, and up
    image = render_world(view, target)
    assert image.shape == (view.size[1], view.size[0]) and image.dtype == np.uint8
    assert np.allclose(_marker_centre(image), view.pixel_of(np.array(target)), atol=0.05)
    expected_norm = (0.5 - target[0] / GUESTRIN_SCREEN_MM[0], 0.5 + target[1] / GUESTRIN_SCREEN_MM[1])
    assert np.allclose(_norm_of(view.size, _marker_centre(image)), expected_norm, atol=1e-4)
    # the marker's extent: MARKER_MM radius, in px
    _, xs = np.nonzero(image != SCREEN_GRAY)
    assert (xs.max() - xs.min() + 1) == pytest.approx(2 * MARKER_MM * view.size[0] / GUESTRIN_SCREEN_MM[0], abs=2)
    assert (image == 255).any()  # the white ring
    assert (render_world(view, None) == SCREEN_GRAY).all()
    assert (render_world(view, (1e4, 0.0)) == SCREEN_GRAY).all()  # off the screen: nothing drawn, no error
    edge = render_world(view, (188.5, 0.0))  # on the edge: half a marker
    assert 0 < (edge != SCREEN_GRAY).sum() < (image != SCREEN_GRAY).sum()


def test_the_target_is_the_latest_shown_else_the_scripts() -> None:
    timeline = Timeline((0.0, 0.0))
    timeline.cut(0)
    timeline.extend(plan([Fixation((50.0, 0.0), 1.0), Saccade((-50.0, 20.0)), Pursuit((50.0, 20.0), 10.0)],
                         (0.0, 0.0), 0, np.array([0.0, 0.0, 600.0])))
    pieces = timeline.pieces
    saccade_to_fix = pieces[1]  # the first saccade (0, 0) -> (50, 0): its target from its start
    assert saccade_to_fix.b == (50.0, 0.0)
    assert script_target(timeline, saccade_to_fix.start_us + 1) == (50.0, 0.0)
    pursuit = pieces[-1]
    mid = (pursuit.start_us + pursuit.end_us) // 2
    assert script_target(timeline, mid) == pytest.approx((0.0, 20.0), abs=1e-6)  # the pursuit's moving point
    track = TargetTrack()
    track.shown((10.0, 10.0), 5_000_000)
    track.shown((20.0, 20.0), 6_000_000)
    assert track.at(4_999_999, timeline) == script_target(timeline, 4_999_999)
    assert track.at(5_000_000, timeline) == (10.0, 10.0) and track.at(6_500_000, timeline) == (20.0, 20.0)
    track.shown((30.0, 30.0), 5_500_000)  # an earlier onset replaces the later target, as the subject's plan
    assert track.at(6_500_000, timeline) == (30.0, 30.0)


# --- the real client -------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["gray", "bgr", "jpeg"])
def test_real_client_receives_world_frames_that_show_the_stimulus(server, device_of, subscribe, fmt: str) -> None:
    srv = server(scene="guestrin2006", world_rate_hz=30, frame_rate_hz=0)
    device = device_of(srv)
    sub = subscribe(device, ["frame.world", "notify.frame_publishing", "notify.test.hello"])
    subscribed(device, sub)  # before the plugin starts: its notification must not go out before we listen
    assert device.request_plugin_start("Frame_Publisher", {"format": fmt}) == "Message forwarded."
    assert wait_for(sub, topic_is("notify.frame_publishing.started")).payload["format"] == fmt
    onset = device.request_current_pupil_time() + 0.3
    device.send_notification({"subject": "eyehil.stimulus", "norm_pos": [0.25, 0.8], "timestamp": onset})
    before = after = 0
    last_index = -1
    while after < 3:
        m = wait_for(sub, lambda m: m.topic == "frame.world" and m.payload["format"] == fmt)
        payload, raw = m.payload, m.raw_data
        assert (payload["width"], payload["height"]) == (640, 510) and len(raw) == 1
        assert payload["index"] > last_index
        last_index = payload["index"]
        if fmt == "gray":
            assert len(raw[0]) == 640 * 510
        elif fmt == "bgr":
            assert len(raw[0]) == 640 * 510 * 3
        norm = _norm_of((640, 510), _marker_centre(_decode(payload, raw[0])))
        if payload["timestamp"] < onset - 1e-3:
            assert norm == pytest.approx((0.5, 0.5), abs=1.5 / 510)  # the subject's start: the screen centre
            before += 1
        elif payload["timestamp"] > onset + 1e-3:
            assert norm == pytest.approx((0.25, 0.8), abs=1.5 / 510)
            after += 1
    assert before >= 1


def test_stop_plugin_stops_world_frames(server, device_of, subscribe) -> None:
    srv = server(world_rate_hz=50, frame_rate_hz=0)
    device = device_of(srv)
    sub = subscribe(device, ["frame.world", "notify.frame_publishing", "notify.test.hello"])
    subscribed(device, sub)  # before the plugin starts: its notification must not go out before we listen
    wait_for(sub, topic_is("frame.world"))
    device.send_notification({"subject": "stop_plugin", "name": "Frame_Publisher"})
    wait_for(sub, topic_is("notify.frame_publishing.stopped"))
    stopped_at = srv.counters["world_published"] + srv.counters["world_dropped"]
    exposures = srv.counters["exposures"]
    eventually(srv, lambda: srv.counters["exposures"] > exposures + 250)  # a second of exposures at 250 Hz
    assert srv.counters["world_published"] + srv.counters["world_dropped"] <= stopped_at + 2  # at most QUEUE waiting


# --- a raw pyzmq script, as pupil-helpers' recv_world_video_frames.py ---------------------------------------
def test_raw_script_reshapes_bgr_world_frames(server) -> None:
    srv = server(scene="blignaut2014", world_rate_hz=30, frame_rate_hz=0, world_width_px=320)
    ctx = zmq.Context()
    ctx.rcvtimeo, ctx.linger = 10_000, 0
    try:
        req = ctx.socket(zmq.REQ)
        req.connect(f"tcp://127.0.0.1:{srv.port}")
        req.send_string("SUB_PORT")
        sub_port = req.recv_string()
        notification = {"subject": "start_plugin", "name": "Frame_Publisher", "args": {"format": "bgr"}}
        req.send_string("notify.start_plugin", flags=zmq.SNDMORE)
        req.send(msgpack.packb(notification, use_bin_type=True))
        assert req.recv_string() == "Message forwarded."
        sub = ctx.socket(zmq.SUB)
        sub.connect(f"tcp://127.0.0.1:{sub_port}")
        sub.setsockopt_string(zmq.SUBSCRIBE, "frame.world")
        while True:
            topic, payload, *extra = sub.recv_multipart()
            msg = msgpack.loads(payload, raw=False)
            if msg["format"] == "bgr":
                break
        assert topic == b"frame.world" and msg["topic"] == "frame.world" and len(extra) == 1
        screen_w, screen_h = srv.subject.solver.scene.screen.size
        height = 2 * round(320 * screen_h / screen_w / 2)
        image = np.frombuffer(extra[0], dtype=np.uint8).reshape(msg["height"], msg["width"], 3)
        assert image.shape == (height, 320, 3) and {"index", "timestamp"} <= msg.keys()
        assert image.min() == 0 and image.max() == 255  # the marker's black and white rings on the gray screen
    finally:
        ctx.destroy(linger=0)
