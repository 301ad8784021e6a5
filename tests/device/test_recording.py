"""Recordings (docs/recording.md) and the host's geometry file: write, read back, refuse what is broken."""

from __future__ import annotations

import json

import numpy as np
import pytest
from device_helpers import query

from eyehil.analysis.study.bridge import tracker_geometry
from eyehil.drivers.client import open_tracker
from eyehil.drivers.recording import Recorder, RecordingError, read_recording
from eyehil.drivers.setup_file import load_geometry
from eyehil.emulator.device.setup_file import write_geometry
from eyehil.emulator.scene import load_scene


def _record(path, count: int = 300) -> tuple[list, list[int]]:
    with open_tracker(f"loop://?{query(scene='blignaut2014', rate=250, latency=0.05)}") as tracker:
        tracker.configure(leds=1)
        sync = tracker.sync_clock(2)
        tracker.start()
        samples, onsets = [], []
        with Recorder(path, tracker, clock_sync=sync, note="test") as rec:
            for i, sample in enumerate(tracker.samples(count=count)):
                if i in (50, 150):
                    onsets.append(tracker.stimulus(i, 100.0 + i, 80.0))
                    rec.target(i, 100.0 + i, 80.0, device_us=onsets[-1], label=f"t{i}")
                rec.write(sample)
                samples.append(sample)
            tracker.stop()
            rec.close(tracker.stats.as_dict(), tracker.status())
    return samples, onsets


def test_round_trip(tmp_path) -> None:
    path = tmp_path / "run.jsonl"
    samples, onsets = _record(path)
    rec = read_recording(path)
    assert rec.complete and len(rec) == len(samples) == 300
    assert rec.header["device"]["camera_width"] == 1600 and rec.header["configuration"]["leds"] == 1
    assert rec.header["clock_sync"]["rtt_us"] >= 0 and rec.header["note"] == "test"
    np.testing.assert_array_equal(rec.device_us, [s.device_us for s in samples])
    np.testing.assert_array_equal(rec.frame_id, [s.frame_id for s in samples])
    assert rec.centre.shape == (300, 2, 2) and rec.glints.shape == (300, 2, 1, 2)
    np.testing.assert_array_equal(rec.centre[:, 1, 0], [s.eyes[1].centre_x for s in samples])  # float32 exact
    labels = rec.target_id
    assert set(labels[rec.device_us < onsets[0]]) == {-1}
    assert set(labels[(rec.device_us >= onsets[0]) & (rec.device_us < onsets[1])]) == {50}
    assert set(labels[rec.device_us >= onsets[1]]) == {150}
    assert [t["label"] for t in rec.targets] == ["t50", "t150"]
    assert rec.end["status"]["samples_sent"] >= 300


def test_cut_short_file_is_read_up_to_the_break(tmp_path) -> None:
    path = tmp_path / "run.jsonl"
    _record(path, 40)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-2]) + "\n" + lines[-2][:25])  # no end record, half a sample
    rec = read_recording(path)
    assert not rec.complete and len(rec) == 39  # the 40th sample was cut in half, the end record lost


@pytest.mark.parametrize("text", ["not json\n{}\n", json.dumps({"format": "other"}) + "\n",
                                  json.dumps({"format": "eyehil-recording", "version": 1}) + '\n{"type": "x"}\n'])
def test_malformed_recordings_are_refused(tmp_path, text: str) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text(text)
    with pytest.raises(RecordingError):
        read_recording(path)


@pytest.mark.parametrize("scene_name", ["guestrin2006", "blignaut2014"])
def test_geometry_file_round_trip(tmp_path, scene_name: str) -> None:
    scene = load_scene(scene_name)
    loaded = load_geometry(write_geometry(scene, tmp_path / "g.toml"))
    expected = tracker_geometry(scene)
    assert loaded.scene == scene_name
    np.testing.assert_array_equal(loaded.geometry.camera.K, expected.camera.K)
    np.testing.assert_array_equal(loaded.geometry.camera.R, expected.camera.R)
    np.testing.assert_array_equal(loaded.geometry.leds, expected.leds)
    np.testing.assert_array_equal(loaded.geometry.screen.centre, expected.screen.centre)
    assert loaded.geometry.camera.image_size == expected.camera.image_size


def test_geometry_file_errors_name_the_key(tmp_path) -> None:
    path = tmp_path / "g.toml"
    path.write_text('format = "eyehil-geometry"\nversion = 1\n[camera]\nmatrix_px = [1, 2]\n')
    with pytest.raises(ValueError, match=r"camera\.resolution_px"):
        load_geometry(path)
