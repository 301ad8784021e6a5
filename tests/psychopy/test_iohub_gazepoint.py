"""PsychoPy ioHub with psychopy-eyetracker-gazepoint, unmodified, against the Open Gaze server: configure the
GP3 eye tracker, run its (tracker-paced) calibration, record, and receive binocular sample events whose gaze
lies within 1 deg of the target the subject looks at."""

from __future__ import annotations

import json

from opengaze_helpers import angle_deg, start_server
from psychopy_helpers import Script, psychopy_python

TARGET = (0.3, 0.7)  # screen fractions, top-left origin
SETTLE_S = 0.6  # the subject's latency (0.2 s) and saccade, with a margin
RECORD_S = 2.0


def test_iohub_calibrates_and_records_binocular_gaze() -> None:
    psychopy_python()  # skip early, before a server starts
    srv = start_server()
    script = None
    try:
        scene = srv.subject.solver.scene
        script = Script("iohub_gazepoint.py", srv.port, RECORD_S)
        result = json.loads(script.line("CALIBRATION"))
        assert isinstance(result, dict), (result, srv.all_counters(), script.tail())  # an int: an ioHub error code
        points = [(result[f"CALX{k}"], result[f"CALY{k}"]) for k in range(1, 10)]
        assert len(points) == 9 and int(result["SUMMARY"]["VALID_POINTS"]) == 9
        for k, target in enumerate(points, 1):
            for eye in "LR":
                assert result[f"{eye}V{k}"] == 1
                assert angle_deg(scene, target, (result[f"{eye}X{k}"], result[f"{eye}Y{k}"])) < 1.0
        script.line("READY")
        shown_s = (srv.device.clock.now_us() - srv.device.t0_us) / 1e6
        srv.show(TARGET)
        script.send("go")
        script.line("DONE")
    finally:
        if script is not None:
            script.close()
        srv.close()
    settled = script.samples(after_s=shown_s + SETTLE_S)
    assert len(settled) >= 30, script.tail()
    for s in settled:
        assert s["status"] == 0  # both eyes valid
        for eye in ("left", "right"):
            assert angle_deg(scene, TARGET, tuple(s["gaze"][eye])) < 1.0, s
        assert all(0.0 < px < 100.0 for px in s["pupil_px"]) and all(2.0 < mm < 8.0 for mm in s["pupil_mm"])
