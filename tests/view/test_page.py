"""The live view in a real headless Chromium: loads, eye images with overlays, controls, calibration, gaze,
disconnection and reconnection. Every wait is on a condition of the page's state (window.eyehilView)."""

from __future__ import annotations

import threading

import pytest
from view_helpers import WAIT_MS, start_device

from eyehil.drivers.setup_file import load_geometry
from eyehil.drivers.view.server import ViewServer
from eyehil.protocols.native import DEVICE_TYPES
from eyehil.protocols.samples import Features
from eyehil.protocols.stream import NativeReceiver, Received

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def status(page) -> str:
    return page.inner_text("#status")


def test_page_loads_and_streams(page, view):
    assert page.title() == "eyehil live view"
    page.wait_for_function("window.eyehilView.streaming && window.eyehilView.ticks > 3", timeout=WAIT_MS)
    assert status(page) == "streaming"
    assert "eyehil virtual tracker" in page.inner_text("#device")
    page.wait_for_function("window.eyehilView.stats.rate_hz > 0", timeout=WAIT_MS)


class FeatureTap:
    """What the device sent, decoded independently of the view: (frame id, eye) -> pupil centre (px)."""

    def __init__(self, core) -> None:
        self.receiver, self.pupils, self.lock = NativeReceiver(accept=DEVICE_TYPES), {}, threading.Lock()
        original = core.read_available

        def read_available(max_bytes=None):
            data = original(max_bytes)
            with self.lock:
                for event in self.receiver.feed(data):
                    if isinstance(event, Received) and isinstance(event.message, Features):
                        for e in event.message.eyes:
                            self.pupils[(event.message.frame_id, int(e.eye))] = (e.centre_x, e.centre_y)
            return data
        core.read_available = read_available


DRAWN = """() => {
  const o = window.eyehilView.overlay.right;
  if (!o || o.source !== "image" || !o.pupil) return null;
  const c = document.getElementById("eye-right"), d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
  let n = 0, sx = 0, sy = 0;
  for (let y = 20; y < c.height; y++) for (let x = 0; x < c.width; x++) {  // below the label box
    const i = 4 * (y * c.width + x);
    if (d[i] < 45 && d[i + 1] < 45 && d[i + 2] < 45) { n++; sx += x; sy += y; }
  }
  return {overlay: o, dark: n ? [sx / n, sy / n, n] : null};
}"""


def test_eye_image_updates_and_the_pupil_overlay_lies_on_the_sent_feature(browser, geometry_file):
    runner = start_device()
    tap = FeatureTap(runner.core)
    geometry = load_geometry(geometry_file()).geometry
    try:
        with ViewServer(runner.url, geometry=geometry) as view:
            page = browser.new_page()
            page.goto(view.address)
            page.wait_for_function("window.eyehilView.imagesDrawn > 2", timeout=WAIT_MS)
            first = page.locator("#eye-right").screenshot()
            seen = page.evaluate("window.eyehilView.overlay.right.frame_id")
            page.wait_for_function(f"window.eyehilView.overlay.right.frame_id > {seen}", timeout=WAIT_MS)
            page.wait_for_function(f"window.eyehilView.overlay.right.frame_id > {seen}", timeout=WAIT_MS)
            assert page.locator("#eye-right").screenshot() != first
            drawn = page.evaluate(DRAWN)
            page.close()
    finally:
        runner.close()
    overlay = drawn["overlay"]
    with tap.lock:
        sent = tap.pupils[(overlay["frame_id"], 0)]
    # The overlay is where the device's feature of that exposure is, in the image's pixels ...
    assert abs(overlay["pupil"]["x"] - (sent[0] - overlay["origin"][0])) <= 2
    assert abs(overlay["pupil"]["y"] - (sent[1] - overlay["origin"][1])) <= 2
    # ... and on the dark pupil of the image drawn beneath it.
    assert drawn["dark"] is not None and drawn["dark"][2] > 100
    assert abs(drawn["dark"][0] - overlay["pupil"]["x"]) <= 2
    assert abs(drawn["dark"][1] - overlay["pupil"]["y"]) <= 2


def test_stop_and_start_from_the_page(page):
    page.wait_for_function("window.eyehilView.streaming", timeout=WAIT_MS)
    page.click("#stop")
    page.wait_for_function("!window.eyehilView.streaming", timeout=WAIT_MS)
    assert status(page) == "connected, idle"
    page.wait_for_function("window.eyehilView.stats.rate_hz === 0", timeout=WAIT_MS)
    page.click("#start")
    page.wait_for_function("window.eyehilView.streaming && window.eyehilView.stats.rate_hz > 50", timeout=WAIT_MS)
    assert status(page) == "streaming"


GAZE_NEAR_TARGET = """(limit) => {
  const v = window.eyehilView;
  if (!v.gaze || !v.target) return false;
  return Math.hypot(v.gaze[0] - v.target[0], v.gaze[1] - v.target[1]) < limit;
}"""


def test_calibrate_from_the_page_then_the_gaze_follows_the_grid(page):
    page.wait_for_function("window.eyehilView.streaming", timeout=WAIT_MS)
    page.select_option("#method", "guestrin")
    page.click("#calibrate")
    page.wait_for_function("window.eyehilView.calibration !== null", timeout=WAIT_MS)
    calibration = page.evaluate("window.eyehilView.calibration")
    assert calibration["ok"], calibration["error"]
    errors = [p["error_deg"] for p in calibration["points"]]
    assert len(errors) == 4 and all(0 <= e < 1.0 for e in errors)
    assert float(page.inner_text("#mean-error")) == pytest.approx(calibration["mean_error_deg"], abs=0.01)
    assert page.locator("#calibration tr").count() == 5  # header + the four validation targets
    page.select_option("#script", "grid")
    page.wait_for_function("window.eyehilView.script.name === 'grid' && window.eyehilView.target", timeout=WAIT_MS)
    first = page.evaluate("window.eyehilView.target")
    page.wait_for_function(GAZE_NEAR_TARGET, arg=10.0, timeout=WAIT_MS)  # mm on the screen
    page.wait_for_function(f"window.eyehilView.target[0] !== {first[0]} || window.eyehilView.target[1] !== {first[1]}",
                           timeout=WAIT_MS)
    page.wait_for_function(GAZE_NEAR_TARGET, arg=10.0, timeout=WAIT_MS)


def test_a_closed_device_shows_disconnected_and_the_page_reconnects(browser, geometry_file):
    runner = start_device()
    port = int(runner.url.rsplit(":", 1)[1])
    geometry = load_geometry(geometry_file()).geometry
    try:
        with ViewServer(runner.url, geometry=geometry, timeout=1.0, retry_s=0.2) as view:
            page = browser.new_page()
            page.goto(view.address)
            page.wait_for_function("window.eyehilView.streaming", timeout=WAIT_MS)
            runner.close()
            page.wait_for_function("!window.eyehilView.connected", timeout=WAIT_MS)
            assert status(page) == "disconnected"
            assert page.evaluate("document.body.className") == "disconnected"
            runner = start_device(port=port)
            ticks = page.evaluate("window.eyehilView.ticks")
            page.wait_for_function("window.eyehilView.connected && window.eyehilView.streaming", timeout=WAIT_MS)
            page.wait_for_function(f"window.eyehilView.ticks > {ticks} && window.eyehilView.stats.rate_hz > 50",
                                   timeout=WAIT_MS)
            assert status(page) == "streaming"
            page.close()
    finally:
        runner.close()


def test_host_detection_lies_within_2_px_of_the_ground_truth_the_device_sent(browser, device, geometry_file):
    geometry = load_geometry(geometry_file()).geometry
    with ViewServer(device.url, geometry=geometry, stream="detect") as view:
        page = browser.new_page()
        page.goto(view.address)
        ready = "(o => o && o.truth && o.pupil && o.source === 'image')(window.eyehilView.overlay.right)"
        page.wait_for_function(ready, timeout=WAIT_MS)
        overlay = page.evaluate("window.eyehilView.overlay.right")
        assert page.evaluate("window.eyehilView.hello.stream") == "detect"
        page.close()
    detected, truth = overlay["pupil"], overlay["truth"]
    assert abs(detected["x"] - truth["x"]) <= 2 and abs(detected["y"] - truth["y"]) <= 2
    assert abs(truth["x"] - (truth["sensor_x"] - overlay["origin"][0])) < 1e-6


def test_blink_from_the_page_closes_the_emulated_eyes(browser, device, geometry_file):
    from eyehil.emulator.device.cli import ViewBlink

    geometry = load_geometry(geometry_file()).geometry
    with ViewServer(device.url, geometry=geometry, oracle=ViewBlink(device.core)) as view:
        page = browser.new_page()
        page.goto(view.address)
        page.wait_for_function("window.eyehilView.eyes.right.tickRecord && window.eyehilView.streaming",
                               timeout=WAIT_MS)
        assert not page.evaluate("window.eyehilView.eyes.right.tickRecord.blink")
        assert page.is_enabled("#blink")
        page.click("#blink")
        page.wait_for_function("window.eyehilView.eyes.right.tickRecord.blink", timeout=WAIT_MS)
        page.wait_for_function("!window.eyehilView.eyes.right.tickRecord.blink", timeout=WAIT_MS)  # and open again
        page.close()


def test_blink_is_refused_without_an_emulator_in_process(page):
    page.wait_for_function("window.eyehilView.hello !== null", timeout=WAIT_MS)
    assert not page.is_enabled("#blink")


def test_blignaut_calibration_on_a_binocular_device(browser, geometry_file):
    runner = start_device("blignaut2014")
    geometry = load_geometry(geometry_file("blignaut2014")).geometry
    try:
        with ViewServer(runner.url, geometry=geometry, plan_timing={"settle_s": 0.4, "collect_s": 0.15}) as view:
            page = browser.new_page()
            page.goto(view.address)
            page.wait_for_function("window.eyehilView.overlay.right && window.eyehilView.overlay.left",
                                   timeout=WAIT_MS)
            page.select_option("#method", "blignaut")
            page.click("#calibrate")
            page.wait_for_function("window.eyehilView.calibrating === 'blignaut'", timeout=WAIT_MS)
            page.wait_for_function("window.eyehilView.calibration !== null", timeout=WAIT_MS)
            calibration = page.evaluate("window.eyehilView.calibration")
            page.wait_for_function("window.eyehilView.streaming && window.eyehilView.gaze !== null", timeout=WAIT_MS)
            page.close()
    finally:
        runner.close()
    assert calibration["ok"] and calibration["method"] == "blignaut", calibration["error"]
    assert len(calibration["points"]) == 4 and all(p["error_deg"] < 1.5 for p in calibration["points"])
