"""The view's parts without a browser: bounded fan-out, gaze scripts, payloads, the video file, the command."""

from __future__ import annotations

import argparse
import asyncio
import concurrent.futures
import json

import aiohttp
import cv2
import numpy as np
import pytest

from eyehil.drivers.setup_file import load_geometry
from eyehil.drivers.view.hub import CLIENT_QUEUE, INBOX, Hub
from eyehil.drivers.view.overlay import draw_overlay, features_panel
from eyehil.drivers.view.payload import HEADER_LENGTH, eye_record, image_message
from eyehil.drivers.view.scripts import GazeScript
from eyehil.drivers.view.server import MAX_COMMAND_BYTES, ViewServer
from eyehil.drivers.view.video import VideoRecorder
from eyehil.protocols.enums import Eye, GlintFlags, PupilFlags
from eyehil.protocols.images import Image
from eyehil.protocols.samples import EyeFeatures, Glint

RECORD = EyeFeatures(Eye.RIGHT, PupilFlags.DETECTED, 200.5, 150.25, 30.0, 28.0, 12.0, 0.9,
                     (Glint(0, 210.0, 152.0), Glint(1, 0.0, 0.0, GlintFlags(0))))


def run_async(scenario):
    """Run a coroutine function on a fresh loop in its own thread (Playwright's sync API may own this one's)."""
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, scenario()).result()


def test_a_page_that_never_reads_loses_its_oldest_messages_and_memory_stays_bounded():
    async def scenario():
        hub = Hub(asyncio.get_running_loop())
        stalled, reading = hub.attach(), hub.attach()
        got = []
        for i in range(1000):
            hub.publish({"type": "tick", "i": i, "stats": {}})
            if i % 10 == 9:
                got += await reading.get_all()
        return hub, stalled, reading, got
    hub, stalled, reading, got = run_async(scenario)
    assert len(stalled.queue) == CLIENT_QUEUE and stalled.dropped == 1000 - CLIENT_QUEUE
    assert [m["i"] for m in stalled.queue] == list(range(1000 - CLIENT_QUEUE, 1000))  # the newest kept
    assert len(got) == 1000 and reading.dropped == 0
    assert hub.dropped == 1000 - CLIENT_QUEUE


def test_the_threadsafe_inbox_is_bounded_when_the_loop_does_not_run():
    loop = asyncio.new_event_loop()
    try:
        hub = Hub(loop)
        for i in range(3 * INBOX):
            hub.publish_threadsafe({"type": "tick", "i": i, "stats": {}})
        assert len(hub._inbox) == INBOX and hub.dropped == 2 * INBOX
    finally:
        loop.close()


def test_sticky_messages_reach_a_late_page():
    async def scenario():
        hub = Hub(asyncio.get_running_loop())
        hub.publish({"type": "hello", "model": "x"})
        hub.publish({"type": "tick", "stats": {}})
        return await hub.attach().get_all()
    assert [m["type"] for m in run_async(scenario)] == ["hello"]


@pytest.mark.parametrize("name", ["fixations", "pursuit", "grid"])
def test_gaze_scripts_stay_on_the_screen_and_move(name):
    script = GazeScript(name, (377.0, 301.0))
    path = np.array([script.target_at(t) for t in np.arange(0, 30, 0.1)])
    assert np.all((path >= 0) & (path <= [377.0, 301.0]))
    assert len(np.unique(path, axis=0)) > 5


def test_grid_dwells_then_moves_row_by_row():
    script = GazeScript("grid", (300.0, 200.0), dwell_s=1.0)
    assert script.target_at(0.2) == script.target_at(0.9) == (30.0, 20.0)
    assert script.target_at(1.1) == (150.0, 20.0)
    with pytest.raises(ValueError):
        GazeScript("saccades", (1.0, 1.0))


def test_eye_record_keeps_valid_glints_and_the_ellipse():
    r = eye_record(RECORD)
    assert r["detected"] and (r["x"], r["y"], r["a"], r["b"], r["angle"]) == (200.5, 150.25, 30.0, 28.0, 12.0)
    assert r["glints"] == [{"led": 0, "x": 210.0, "y": 152.0}]


def test_image_message_round_trip():
    pixels = np.full((240, 320), 90, np.uint8)
    message = image_message(Eye.RIGHT, 7, (100, 50), pixels, 1234, eye_record(RECORD))
    (length,) = HEADER_LENGTH.unpack_from(message)
    header = json.loads(message[4:4 + length])
    assert header["frame_id"] == 7 and (header["roi_x"], header["roi_y"]) == (100, 50)
    assert header["record"]["x"] == 200.5
    decoded = cv2.imdecode(np.frombuffer(message[4 + length:], np.uint8), cv2.IMREAD_GRAYSCALE)
    assert decoded.shape == (240, 320) and abs(int(decoded.mean()) - 90) <= 1


def test_the_features_panel_draws_the_pupil_where_the_record_says():
    record = eye_record(RECORD)
    panel, origin = features_panel(record)
    dark = np.argwhere(panel[..., 0] < 40)
    cy, cx = dark.mean(0)
    assert abs(cx + origin[0] - 200.5) < 1 and abs(cy + origin[1] - 150.25) < 1
    drawn = draw_overlay(panel.copy(), record, origin)
    assert (drawn != panel).any()


@pytest.mark.parametrize("suffix", [".mp4", ".png"])
def test_the_video_holds_the_frames_written(tmp_path, suffix):
    recorder = VideoRecorder(tmp_path / f"view{suffix}", fps=1000.0)
    record = eye_record(RECORD)
    for k in range(5):  # frames that differ (an animated PNG merges identical ones)
        pixels = np.full((240, 320), 120, np.uint8)
        pixels[100:140, 140 + 10 * k:180 + 10 * k] = 10
        recorder.image(Image(k, Eye.RIGHT, 0, 0, pixels), record)
        recorder._last_write = 0.0  # one frame per tick, whatever the wall clock
        recorder.tick({"eyes": {"right": record}})
    path = recorder.close()
    assert recorder.frames == 5
    if suffix == ".mp4":
        capture = cv2.VideoCapture(str(path))
        assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == 5
        ok, frame = capture.read()
        assert ok and frame.shape == (240, 320, 3)
    else:
        ok, animation = cv2.imreadanimation(str(path))
        assert ok and len(animation.frames) == 5 and animation.frames[0].shape[:2] == (240, 320)


def test_eyehil_view_serves_a_loop_device_for_a_while(capsys, tmp_path):
    from eyehil.drivers.view.cli import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers(dest="command"))
    video = tmp_path / "view.mp4"
    args = parser.parse_args(["view", "loop://?scene=guestrin2006", "--port", "0", "--duration", "1.5",
                              "--record-video", str(video)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "view: http://127.0.0.1:" in out and f"video: {video}" in out
    assert video.stat().st_size > 0


def test_hostile_page_messages_are_ignored_or_refused_and_the_view_goes_on(geometry_file):

    async def hostile(address: str) -> tuple[list[dict], dict, int]:
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(address + "ws") as ws:
                for junk in ("not json", "[1, 2]", '{"cmd": 5}', '{"cmd": "fps", "value": 1e300}',
                             '{"cmd": "format-disk"}', '{"cmd": "blink"}',
                             '{"cmd": "script", "name": "' + "x" * 1000 + '"}'):
                    await ws.send_str(junk)
                states = []
                while not any("unknown script" in (s.get("error") or "") for s in states):
                    message = await ws.receive(timeout=60)
                    if message.type == aiohttp.WSMsgType.TEXT and json.loads(message.data)["type"] == "state":
                        states.append(json.loads(message.data))
            async with http.ws_connect(address + "ws") as ws:  # too long: the server closes this socket
                await ws.send_str('{"cmd": "stop", "pad": "' + "x" * MAX_COMMAND_BYTES + '"}')
                while (await ws.receive(timeout=60)).type not in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED,
                                                                  aiohttp.WSMsgType.ERROR):
                    pass
                code = ws.close_code
            async with http.get(address + "stats") as response:
                return states, await response.json(), code

    geometry = load_geometry(geometry_file()).geometry
    with ViewServer("loop://?scene=guestrin2006", geometry=geometry) as view:
        states, stats, code = run_async(lambda: hostile(view.address))
        assert view.session.tracker is not None and view.session.tracker.streaming  # the oversized "stop" never ran
    assert any("cannot be made to blink" in (s.get("error") or "") for s in states)
    assert code == aiohttp.WSCloseCode.MESSAGE_TOO_BIG
    assert stats["page_fps"] == [] and stats["session"]["reconnects"] == 1


def test_the_live_state_is_bounded_and_a_tick_carries_at_most_max_tick_samples_rows():
    from eyehil.drivers.view.live import MAX_PENDING, MAX_RECORDS, MAX_TICK_SAMPLES, LiveStream
    from eyehil.drivers.wire import Sample

    live = LiveStream()
    samples = [Sample(i, i, 4000 * i, 4000 * i + 5000, (RECORD,)) for i in range(3 * MAX_PENDING)]
    live.add(samples, np.full((len(samples), 2), np.nan), None)
    assert len(live.records) == MAX_RECORDS and len(live.pending) == MAX_PENDING
    assert (samples[-1].frame_id, 0) in live.records and (0, 0) not in live.records  # the newest kept
    tick = live.tick(None, {}, (10.0, 20.0))
    assert 0 < len(tick["samples"]) <= MAX_TICK_SAMPLES and live.pending == []
    assert tick["eyes"]["right"]["frame_id"] == samples[-1].frame_id and tick["target"] == [10.0, 20.0]
    assert tick["samples"][-1][1] == pytest.approx(0.9)  # confidence of the right eye; no left eye, no gaze
    assert tick["samples"][-1][2:] == [None, None, None]


def test_a_slow_page_loses_images_and_ticks_before_state_changes():
    async def scenario():
        hub = Hub(asyncio.get_running_loop())
        page = hub.attach()
        hub.publish({"type": "state", "calibrating": "guestrin"})
        for i in range(3 * CLIENT_QUEUE):
            hub.publish(b"image %d" % i if i % 2 else {"type": "tick", "i": i, "stats": {}})
        hub.publish({"type": "calibration", "ok": True})
        return list(page.queue)
    queued = run_async(scenario)
    assert len(queued) == CLIENT_QUEUE
    assert queued[0] == {"type": "state", "calibrating": "guestrin"} and queued[-1]["type"] == "calibration"
    assert queued[-2] == b"image %d" % (3 * CLIENT_QUEUE - 1)  # the newest of the rest kept


def test_images_are_thinned_by_device_time_not_by_arrival():
    """Images that arrive together (a bursty link or loop) are all shown; only images exposed less than
    1 / max_image_hz after the last one shown are skipped; a device time that goes back is a new stream."""
    from eyehil.drivers.view.live import LiveStream
    from eyehil.drivers.wire import ReceivedImage

    live = LiveStream(max_image_hz=120.0)
    pixels = np.zeros((4, 4), np.uint8)

    def got(frame: int, device_ms: float) -> ReceivedImage:  # every one arrives at the same host time
        return ReceivedImage(Image(frame, Eye.RIGHT, 0, 0, pixels), int(device_ms * 1000), 0, frame)

    shown = [live.image(got(k, t)) is not None for k, t in enumerate((0.0, 16.7, 33.3, 35.0, 50.0, 10.0))]
    assert shown == [True, True, True, False, True, True]
    assert live.images_skipped == 1
