"""The LSL outlet of type Gaze: a pylsl inlet finds it, reads Pupil-style channel metadata and samples with
explicit timestamps on LSL's clock. Skips (with the reason) where pylsl or liblsl is missing."""

from __future__ import annotations

import math

import numpy as np
import pytest
from zmq_helpers import eventually

from eyehil.emulator.device.lsl.channels import gaze_channels, relay_channels, relay_rows
from eyehil.emulator.device.lsl.library import LslUnavailableError, load_pylsl
from eyehil.emulator.device.pupil.gaze import Block

try:
    pylsl = load_pylsl()
except LslUnavailableError as exc:
    pytest.skip(str(exc), allow_module_level=True)


def _channels(info) -> list[dict[str, str]]:
    """label, eye, type, unit of every channel in the stream's desc/channels."""
    out, node = [], info.desc().child("channels").child("channel")
    while not node.empty():
        out.append({k: node.child_value(k) for k in ("label", "eye", "type", "unit", "coordinate_system")})
        node = node.next_sibling()
    return out


def test_channel_layout() -> None:
    labels = [c.label for c in gaze_channels((0, 1), 1)]
    assert labels[:3] == ["confidence", "norm_pos_x", "norm_pos_y"]
    assert labels[3:9] == ["pupil0_x", "pupil0_y", "diameter0_2d", "confidence0", "glint0_0_x", "glint0_0_y"]
    assert len(labels) == 3 + 2 * 6


def test_inlet_receives_gaze_stream(server) -> None:
    opened = pylsl.local_clock()
    srv = server(scene="guestrin2006", rate_hz=100, lsl=True)
    streams = pylsl.resolve_byprop("source_id", srv.outlet_source_id, timeout=10)
    assert streams, "the outlet was not found"
    inlet = pylsl.StreamInlet(streams[0])
    try:
        info = inlet.info(timeout=10)
        assert info.type() == "Gaze" and info.nominal_srate() == 100 and info.channel_format() == pylsl.cf_double64
        channels = _channels(info)
        assert [c["label"] for c in channels] == [c.label for c in gaze_channels((0,), 2)]
        assert channels[1] == {"label": "norm_pos_x", "eye": "both", "type": "ScreenX", "unit": "normalized",
                               "coordinate_system": "screen"}
        assert channels[3] == {"label": "pupil0_x", "eye": "right", "type": "PupilX", "unit": "pixels",
                               "coordinate_system": "eye0"}
        sample, stamp = inlet.pull_sample(timeout=10)
        assert sample is not None and len(sample) == len(channels)
        assert opened < stamp <= pylsl.local_clock()  # on LSL's clock: an exposure between start-up and now
        values = dict(zip((c["label"] for c in channels), sample, strict=True))
        assert math.isnan(values["norm_pos_x"]) and values["confidence"] == 0  # not calibrated
        assert values["confidence0"] == 1 and 0 < values["pupil0_x"] < 320 and values["diameter0_2d"] > 10
        _second, later = inlet.pull_sample(timeout=10)
        assert later - stamp == pytest.approx(0.01, abs=2e-3)  # explicit mid-exposure times, 100 Hz
    finally:
        inlet.close_stream()
        del inlet
    eventually(srv, lambda: srv.outlet.pushed > 2)


def test_source_id_is_stable_across_restarts_of_the_same_device(server) -> None:
    first = server(scene="guestrin2006", lsl=True)
    source, port = first.outlet_source_id, first.options.port
    first.close()
    again = server(scene="guestrin2006", lsl=True)
    assert again.options.port == port and again.outlet_source_id == source
    assert source.startswith("eyehil-")
    assert server(scene="blignaut2014", lsl=True).outlet_source_id != source


def test_pupil_relay_layout(server) -> None:
    srv = server(scene="blignaut2014", rate_hz=100, lsl=True, lsl_layout="pupil_relay")
    streams = pylsl.resolve_byprop("source_id", srv.outlet_source_id, timeout=10)
    assert streams and streams[0].name() == "pupil_capture" and streams[0].type() == "Gaze"
    inlet = pylsl.StreamInlet(streams[0])
    try:
        channels = _channels(inlet.info(timeout=10))
        labels = [c["label"] for c in channels]
        assert labels[:6] == ["confidence", "norm_pos_x", "norm_pos_y", "gaze_point_3d_x", "gaze_point_3d_y",
                              "gaze_point_3d_z"]
        assert labels[6:9] == ["eye_center0_3d_x", "eye_center0_3d_y", "eye_center0_3d_z"]
        assert labels[12:15] == ["gaze_normal0_x", "gaze_normal0_y", "gaze_normal0_z"]
        assert labels[18:] == ["diameter0_2d", "diameter1_2d", "diameter0_3d", "diameter1_3d"]
        assert channels[21] == {"label": "diameter1_3d", "eye": "left", "type": "Diameter", "unit": "mm",
                                "coordinate_system": "eye1"}
        sample, _stamp = inlet.pull_sample(timeout=10)
        values = dict(zip(labels, sample, strict=True))
        assert values["diameter0_2d"] > 10 and values["diameter1_2d"] > 10 and 2 < values["diameter0_3d"] < 8
        assert math.isnan(values["gaze_point_3d_x"])  # not calibrated
    finally:
        inlet.close_stream()
        del inlet


def test_relay_rows_carry_the_3d_eye_model() -> None:
    n = 3
    block = Block(time_us=np.arange(n), pupil=np.zeros((n, 2, 2)),
                  diameter=np.array([[30.0, 31.0], [30.0, np.nan], [30.0, 31.0]]), confidence=np.ones((n, 2)),
                  glints=np.zeros((n, 2, 1, 2)), gaze=np.array([[0.5, 0.5], [0.25, 0.75], [np.nan, np.nan]]),
                  gaze_confidence=np.array([1.0, 1.0, 0.0]))
    centre, size = np.array([0.0, 0.0, 650.0]), (400.0, 300.0)
    eyes = np.array([[-30.0, 0.0, 0.0], [30.0, 0.0, 0.0]])  # solver order: right (id 0), left (id 1)
    rows = relay_rows(block, (0, 1), centre, size, 4.0, eyes)
    labels = [c.label for c in relay_channels()]
    col = {label: i for i, label in enumerate(labels)}
    point = rows[:, [col["gaze_point_3d_x"], col["gaze_point_3d_y"], col["gaze_point_3d_z"]]]
    assert point[0] == pytest.approx([0.0, 0.0, 650.0]) and point[1] == pytest.approx([100.0, 75.0, 650.0])
    for eye_id in (0, 1):
        c = rows[:, [col[f"eye_center{eye_id}_3d_{a}"] for a in "xyz"]]
        g = rows[:, [col[f"gaze_normal{eye_id}_{a}"] for a in "xyz"]]
        assert c[0] == pytest.approx(eyes[eye_id])
        expected = (point[0] - eyes[eye_id]) / np.linalg.norm(point[0] - eyes[eye_id])
        assert g[0] == pytest.approx(expected) and np.linalg.norm(g[0]) == pytest.approx(1.0)
        assert np.isnan(c[2]).all() and np.isnan(g[2]).all()  # no gaze
    assert np.isnan(rows[1, col["eye_center1_3d_x"]]) and np.isfinite(rows[1, col["eye_center0_3d_x"]])  # not found
