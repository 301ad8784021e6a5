"""PyGaze's Open Gaze client (`pygaze._eyetracker.opengaze.OpenGazeTracker`, python-pygaze 0.7.6), unmodified,
against the emulator: connect (it enables every data field), calibrate, record; the gaze it reports lands
within 1 deg of the target the subject looks at."""

from __future__ import annotations

import csv

import pytest
from opengaze_helpers import DEADLINE_S, angle_deg
from waiting import wait_until

opengaze = pytest.importorskip("pygaze._eyetracker.opengaze", reason="python-pygaze and lxml (test extra)")

TARGET = (0.3, 0.7)  # screen fractions, top-left origin: left of centre, below it
NEXT = (0.7, 0.3)  # where the gaze goes after the samples at TARGET
SETTLE_US = 600_000  # the subject's latency (0.2 s) and saccade, with a margin


# The client's close() closes its socket while its own reader thread may still be in recv (EBADF there).
@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_connect_calibrate_and_read_gaze(server, tmp_path) -> None:
    srv = server()
    scene = srv.subject.solver.scene
    tracker = opengaze.OpenGazeTracker(port=srv.port, logfile=str(tmp_path / "pygaze.tsv"))
    try:
        assert tracker.calibrate_delay(0.3) and tracker.calibrate_timeout(0.6)
        points = tracker.get_calibration_points()
        assert points is not None and len(points) == 9
        result = tracker.calibrate()  # tracker-paced: the subject looks at each point the server announces
        assert len(result) == 9
        for p in result:
            assert p["LV"] and p["RV"]
            for eye in "LR":
                assert angle_deg(scene, (p["CALX"], p["CALY"]), (p[f"{eye}X"], p[f"{eye}Y"])) < 1.0
        ave_error, valid = tracker.calibrate_result_summary()
        assert int(valid) == 9 and 0.0 < float(ave_error) < 50.0  # px of the 1920 x 1080 screen

        shown_us = srv.device.clock.now_us()
        srv.show(TARGET)
        tracker.start_recording()  # returns nothing; the REC records that follow show it worked
        _wait_until(lambda: _near(scene, tracker.sample()), "gaze near the target")
        recording_us = max(srv.device.clock.now_us(), shown_us + SETTLE_US)  # records flow and have settled
        _wait_until(lambda: srv.device.clock.now_us() > recording_us + 1_000_000, "1 s of samples")
        # The client reads in its own thread and close() stops it, dropping what it has not read yet: move the
        # gaze on and wait until the client reports it there, so that it has read every sample before the move.
        moved_us = srv.device.clock.now_us()
        srv.show(NEXT)
        _wait_until(lambda: _near(scene, tracker.sample(), NEXT), "the client read past the first target")
        tracker.stop_recording()
    finally:
        tracker.close()
    with open(tmp_path / "pygaze.tsv") as log:
        rows = list(csv.DictReader(log, delimiter="\t"))
    settled = [r for r in rows if r["TIME_TICK"] and shown_us + SETTLE_US < int(r["TIME_TICK"]) < moved_us]
    assert len(settled) >= 30
    for r in settled:
        assert r["BPOGV"] == "1" and r["LPOGV"] == "1" and r["RPOGV"] == "1" and r["LPV"] == "1"
        for key in ("BPOG", "LPOG", "RPOG", "FPOG"):
            assert angle_deg(scene, TARGET, (float(r[key + "X"]), float(r[key + "Y"]))) < 1.0, (key, r)
        assert 0.0 < float(r["LPD"]) < 100.0 and 0.001 < float(r["LPUPILD"]) < 0.01  # px; m
    counts = [int(r["CNT"]) for r in settled]
    assert counts == sorted(counts) and len(set(counts)) == len(counts)


def _near(scene, xy: tuple[float | None, float | None], target: tuple[float, float] = TARGET) -> bool:
    return xy[0] is not None and angle_deg(scene, target, xy) < 1.0


def _wait_until(condition, what: str) -> None:
    wait_until(condition, what, DEADLINE_S)
