"""Run in PsychoPy's own environment (not the project's): ioHub with psychopy-eyetracker-pupil-labs, unmodified.

    python iohub_pupil.py PORT SECONDS SURFACE

Configures the Pupil Core eye tracker in gaze mode (``pupillometry_only`` off: it subscribes to ``gaze.3d.``
and ``surfaces.SURFACE``) on Pupil Remote at 127.0.0.1:PORT, runs ``runSetupProcedure`` (Pupil Capture's
calibration: ``C`` and the calibration notifications) and prints ``CALIBRATION <result code>`` (again after a
setup the client aborted, ``aborted`` after the code) and the ioHub constant it should equal (``OK
<EYETRACKER_OK>``), then ``READY`` and waits for a line on stdin (the
test shows the subject a target meanwhile), records for SECONDS and prints one ``SAMPLE <json>`` line per
sample event with its gaze in screen fractions (top-left origin; converted back from ioHub's display
coordinates; ``time`` is the event's device_time, the gaze datum's Pupil time in s), then ``DONE``.
"""

import sys

from iohub_launch import session  # beside this script
from psychopy.iohub.constants import EyeTrackerConstants

RETRIES = 2  # setups calibrated again after the client reported an abort (the race in test_iohub_pupil.py)


def calibrate(tracker) -> None:
    """``CALIBRATION <result>`` for each setup (`runSetupProcedure` again after an abort, at most `RETRIES` times;
    such a line ends in ``aborted``), then ``OK <EYETRACKER_OK>``."""
    aborted = EyeTrackerConstants.EYETRACKER_SETUP_ABORTED
    for _ in range(1 + RETRIES):
        result = tracker.runSetupProcedure()
        print(f"CALIBRATION {result}{' aborted' if result == aborted else ''}", flush=True)
        if result != aborted:
            break
    print(f"OK {EyeTrackerConstants.EYETRACKER_OK}", flush=True)


def sample(e, to_fraction) -> dict | None:
    """A monocular or binocular Pupil sample event: its gaze as screen fractions."""
    kind = type(e).__name__
    if "SampleEvent" not in kind:
        return None
    x, y = (e.left_gaze_x, e.left_gaze_y) if kind.startswith("Binocular") else (e.gaze_x, e.gaze_y)
    return {"time": e.device_time, "kind": kind, "gaze": to_fraction(x, y)}


def main() -> int:
    port, seconds, surface = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
    config = {"eyetracker.hw.pupil_labs.pupil_core.EyeTracker": {
        "name": "tracker", "device_timer": {"interval": 0.005},
        "runtime_settings": {
            "pupil_remote": {"ip_address": "127.0.0.1", "port": port, "timeout_ms": 1000},
            "pupil_capture_recording": {"enabled": False, "location": None},
            "pupillometry_only": False, "confidence_threshold": 0.6, "surface_name": surface}}}
    return session(config, calibrate, sample, seconds)


if __name__ == "__main__":
    sys.exit(main())
