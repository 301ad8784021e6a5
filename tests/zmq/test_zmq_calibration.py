"""Calibration through the facade as Pupil Capture runs it, driven by the real client: should_start, reference
data (or the eyehil.stimulus channel), should_stop, then calibration.successful / result.v2 and gaze on the
screen; a calibration without usable data fails with a reason."""

from __future__ import annotations

import numpy as np
import pytest
from pupil_labs.pupil_core_network_client import Device
from zmq_helpers import eventually, subscribed, topic_is, wait_for

SHOW_S = 0.6  # each target's duration (the facade skips the first settle_s = 0.35 s of it)
TARGETS = [(x, y) for y in (0.85, 0.5, 0.15) for x in (0.15, 0.5, 0.85)]
TOLERANCE = 0.03  # normalised screen units: about 11 mm on the 377 mm wide guestrin2006 screen


@pytest.fixture
def client(server):
    """client(**server options) -> (server, device, subscription to notify. pupil. gaze.), all closed after."""
    opened = []

    def make(**options):
        srv = server(clock="fast", **options)  # exact fixations whatever the load: the calibration is deterministic
        device = Device("127.0.0.1", srv.port)
        sub = device.subscribe_in_background(["notify.", "pupil.", "gaze."], buffer_size=5000)
        opened.append((device, sub))
        subscribed(device, sub)
        return srv, device, sub

    yield make
    for device, sub in opened:
        sub.disconnect()
        device.disconnect()


def _until(sub, t_end: float) -> None:
    """Wait until a pupil datum at or after Pupil time `t_end` arrives."""
    wait_for(sub, lambda m: m.topic.startswith("pupil.") and m.payload["timestamp"] >= t_end)


def _finish(device: Device, sub) -> dict:
    """Stop the calibration; the result.v2 payload (asserting the notifications' order)."""
    assert device.request_calibration_stop() == "OK"
    outcome = wait_for(sub, lambda m: m.topic in ("notify.calibration.successful", "notify.calibration.failed"))
    assert outcome.topic == "notify.calibration.successful", outcome.payload.get("reason")
    result = wait_for(sub, topic_is("notify.calibration.result.v2")).payload
    wait_for(sub, topic_is("notify.calibration.stopped"))  # after the outcome (docs/zmq.md)
    return result


def _gaze_near(sub, topic: str, target: tuple[float, float]) -> dict:
    """A gaze datum of `topic` close to `target` (the subject settles there first)."""
    return wait_for(sub, lambda m: m.topic == topic and np.allclose(m.payload["norm_pos"], target, atol=TOLERANCE))


def test_calibration_with_reference_data_gives_gaze(client) -> None:
    _srv, device, sub = client(scene="guestrin2006", eyes="published", eye=17)
    assert device.request_calibration_start() == "OK"
    wait_for(sub, topic_is("notify.calibration.started"))
    t0 = device.current_pupil_time() + 0.1
    ref = [{"norm_pos": list(p), "timestamp": t0 + i * SHOW_S + k / 30}
           for i, p in enumerate(TARGETS) for k in range(int(SHOW_S * 30))]
    device.send_notification({"subject": "calibration.add_ref_data", "ref_data": ref})  # shown on schedule
    _until(sub, t0 + len(TARGETS) * SHOW_S)
    result = _finish(device, sub)
    assert result["gazer_class_name"] == "GazerGuestrin" and result["params"]["n_targets"] == 9
    assert set(result["params"]["eyes"]["0"]) >= {"R", "K", "alpha_deg", "beta_deg"}
    gaze = _gaze_near(sub, "gaze.2d.0.", TARGETS[-1])  # the subject still looks at the last target
    assert gaze.payload["confidence"] == 1.0 and gaze.payload["base_data"][0]["topic"] == "pupil.0.2d"
    device.send_notification({"subject": "eyehil.stimulus", "norm_pos": [0.3, 0.6]})
    _gaze_near(sub, "gaze.2d.0.", (0.3, 0.6))


def test_binocular_calibration_through_the_stimulus_channel(client) -> None:
    _srv, device, sub = client(scene="blignaut2014", eyes="published", eye=3)
    assert device.request_calibration_start() == "OK"
    for target in TARGETS:
        onset = device.current_pupil_time()
        device.send_notification({"subject": "eyehil.stimulus", "norm_pos": list(target), "timestamp": onset})
        _until(sub, onset + SHOW_S)
    result = _finish(device, sub)
    assert result["gazer_class_name"] == "GazerBlignaut" and result["params"]["n_targets"] == 9
    gaze = _gaze_near(sub, "gaze.2d.01.", TARGETS[-1])
    assert sorted(p["id"] for p in gaze.payload["base_data"]) == [0, 1]


def test_calibration_without_data_fails_with_a_reason(client) -> None:
    srv, device, sub = client()
    device.request_calibration_start()
    device.request_calibration_stop()
    failed = wait_for(sub, lambda m: m.topic in ("notify.calibration.successful", "notify.calibration.failed"))
    assert failed.topic == "notify.calibration.failed" and "no calibration target" in failed.payload["reason"]
    assert srv.device.capture.gazer is None


def test_bad_reference_data_is_counted_not_fatal(client) -> None:
    srv, device, _sub = client()
    device.request_calibration_start()
    bad = [{"norm_pos": [0.5]}, {"norm_pos": [float("nan"), 0.5], "timestamp": 1.0}, "x",
           {"norm_pos": [50.0, 50.0], "timestamp": 1.0}]
    device.send_notification({"subject": "calibration.add_ref_data", "ref_data": bad})
    device.send_notification({"subject": "calibration.add_ref_data", "ref_data": "nothing"})
    device.send_notification({"subject": "eyehil.stimulus", "norm_pos": "centre"})
    eventually(srv, lambda: srv.counters["ref_data_refused"] == 4 and srv.counters["targets_refused"] == 2)
    assert device.request_version()
