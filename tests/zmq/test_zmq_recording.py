"""Recordings (`R` ... `r` into `--record-dir`) carry the pupil, gaze, notification and annotation datums in
Pupil's PLData files, read back here as Pupil Player's `load_pldata_file` reads them (pupil-labs/pupil
`file_methods.py`: msgpack pairs [topic, datum bytes] and a float64 `<kind>_timestamps.npy`), within a byte
budget; a session name used twice gets a fresh folder."""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import numpy as np
import pytest
from zmq_helpers import eventually, subscribed, topic_is, wait_for

from eyehil.emulator.device.pupil.recorder import Budget, Recording, open_folder


def load_pldata(folder: Path, kind: str) -> tuple[list[str], list[dict], np.ndarray]:
    """Topics, datums and timestamps of `<kind>.pldata`, read as Pupil Player reads them."""
    timestamps = np.load(folder / f"{kind}_timestamps.npy")
    with (folder / f"{kind}.pldata").open("rb") as fh:
        pairs = list(msgpack.Unpacker(fh, raw=False, use_list=False, strict_map_key=False))
    topics = [topic for topic, _ in pairs]
    datums = [msgpack.unpackb(payload, raw=False, strict_map_key=False) for _, payload in pairs]
    assert timestamps.dtype == np.float64 and len(timestamps) == len(pairs)
    return topics, datums, timestamps


def test_a_recording_holds_pupil_gaze_notifications_and_annotations(server, device_of, subscribe, tmp_path) -> None:
    srv = server(scene="guestrin2006", record_dir=str(tmp_path))
    device = device_of(srv)
    sub = subscribe(device, ["notify.", "gaze.3d."])
    subscribed(device, sub)
    assert device.request_recording_start("trial one") == "OK"
    started = wait_for(sub, topic_is("notify.recording.started")).payload
    folder = Path(started["rec_path"])
    assert folder == tmp_path / "trial_one"
    assert device.request_calibration_start() == "OK"  # the screen-marker calibration runs on its own
    outcome = wait_for(sub, lambda m: m.topic in ("notify.calibration.successful", "notify.calibration.failed"), 60)
    assert outcome.topic == "notify.calibration.successful", outcome.payload.get("reason")
    first_gaze = wait_for(sub, lambda m: m.topic.startswith("gaze.3d.")).payload
    wait_for(sub, lambda m: m.topic.startswith("gaze.3d.") and m.payload["timestamp"] > first_gaze["timestamp"] + 0.2)
    device.send_annotation("trial", duration=0.5, extra={"k": 1})
    eventually(lambda: srv.counters["annotations"] == 1)
    assert device.request_recording_stop() == "OK"
    wait_for(sub, topic_is("notify.recording.stopped"))

    topics, pupils, ts = load_pldata(folder, "pupil")
    assert {"pupil.0.2d", "pupil.0.3d"} <= set(topics) and all(t.startswith("pupil.") for t in topics)
    assert np.array_equal(ts, [p["timestamp"] for p in pupils]) and (np.diff(ts) >= 0).all()
    for topic in set(topics):  # every datum published while recording, none lost: contiguous seq
        seqs = [p["seq"] for t, p in zip(topics, pupils, strict=True) if t == topic]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert len(topics) >= 2 * 250 * 9  # two topics at 250 Hz through a calibration of 9 markers of 1 s
    assert {"id", "norm_pos", "diameter", "confidence", "ellipse"} <= pupils[0].keys()

    topics, gaze, ts = load_pldata(folder, "gaze")
    eyes = first_gaze["topic"].split(".")[2]  # "0" or "01", as this scene's gazer maps
    assert set(topics) == {f"gaze.2d.{eyes}.", f"gaze.3d.{eyes}."}
    assert np.array_equal(ts, [g["timestamp"] for g in gaze])
    assert any(g["timestamp"] == first_gaze["timestamp"] and g["topic"] == first_gaze["topic"] for g in gaze)
    assert all(0 <= g["confidence"] <= 1 and len(g["norm_pos"]) == 2 for g in gaze)

    topics, notes, _ = load_pldata(folder, "notify")
    subjects = [n["subject"] for n in notes]
    for subject in ("recording.started", "calibration.should_start", "calibration.started",
                    "calibration.successful", "calibration.result.v2"):
        assert subject in subjects
    assert all(t == "notify." + n["subject"] for t, n in zip(topics, notes, strict=True))

    topics, annotations, ts = load_pldata(folder, "annotation")
    assert topics == ["annotation"] and annotations[0]["label"] == "trial" and annotations[0]["extra"] == {"k": 1}
    assert ts[0] == annotations[0]["timestamp"]

    info = json.loads((folder / "info.player.json").read_text())
    assert info["recording_name"] == "trial_one" and info["duration_s"] > 9
    assert info["start_time_synced_s"] == pytest.approx(started["start_time_synced_s"], abs=0.1)
    assert srv.counters["recording_errors"] == 0 and srv.counters["recorded_dropped"] == 0
    assert srv.counters["recorded"] == sum(len(load_pldata(folder, k)[0]) for k in ("pupil", "gaze", "notify",
                                                                                    "annotation"))


def test_recordings_stay_within_their_byte_budget(server, device_of, subscribe, tmp_path) -> None:
    budget = 40_000
    srv = server(record_dir=str(tmp_path), record_max_bytes=budget)
    device = device_of(srv)
    sub = subscribe(device, ["notify.", "pupil.0.2d"])
    subscribed(device, sub)
    for _ in range(2):  # the same name twice: a second folder, the budget shared
        assert device.request_recording_start("same") == "OK"
        wait_for(sub, topic_is("notify.recording.started"))
        t_end = wait_for(sub, topic_is("pupil.0.2d")).payload["timestamp"] + 0.5
        wait_for(sub, lambda m, t_end=t_end: m.topic == "pupil.0.2d" and m.payload["timestamp"] > t_end)
        assert device.request_recording_stop() == "OK"
        wait_for(sub, topic_is("notify.recording.stopped"))
    folders = sorted(tmp_path.iterdir())
    assert folders == [tmp_path / "same", tmp_path / "same_1"]
    written = sum(f.stat().st_size for folder in folders for f in folder.iterdir()
                  if f.suffix in (".pldata", ".jsonl"))
    assert 0.5 * budget < written <= budget  # filled, never beyond
    assert srv.counters["recorded_dropped"] > 0 and srv.counters["recording_errors"] == 0
    counts = [len(load_pldata(folder, "pupil")[0]) for folder in folders]
    assert counts[0] > 0 and counts[1] < counts[0]  # the first took most of the budget


def test_recording_unit(tmp_path) -> None:
    first = open_folder(tmp_path, "r")
    assert first == tmp_path / "r" and open_folder(tmp_path, "r") == tmp_path / "r_1"
    with pytest.raises(OSError):
        open_folder(tmp_path, "../x")
    with pytest.raises(OSError):
        open_folder(tmp_path, ".")
    budget = Budget(10_000)
    rec = Recording(first, "r", 100.0, budget)
    datum = msgpack.packb({"topic": "pupil.0.2d", "timestamp": 100.5, "x": 1.0})
    rec.add("pupil.0.2d", datum, 100.5, 101.0)
    rec.add("gaze.3d.0.", msgpack.packb({"topic": "gaze.3d.0."}), float("nan"), 101.0)  # no finite timestamp: now
    rec.add("surfaces.screen", datum, 100.5, 101.0)  # not a recorded kind
    rec.add("pupil.0.2d", b"x" * 20_000, 100.6, 101.0)  # over the budget
    assert rec.written == 2 and rec.dropped == 1
    rec.close(102.0)
    rec.close(103.0)  # idempotent
    topics, datums, ts = load_pldata(first, "pupil")
    assert topics == ["pupil.0.2d"] and datums[0]["x"] == 1.0 and list(ts) == [100.5]
    assert list(load_pldata(first, "gaze")[2]) == [101.0]
    assert load_pldata(first, "notify")[0] == []
    assert json.loads((first / "info.player.json").read_text())["duration_s"] == 2.0
    assert budget.left < 10_000
