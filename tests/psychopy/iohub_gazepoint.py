"""Run in PsychoPy's own environment (not the project's): ioHub with psychopy-eyetracker-gazepoint, unmodified.

    python iohub_gazepoint.py PORT SECONDS

Configures the Gazepoint GP3 eye tracker at 127.0.0.1:PORT, runs its calibration (the tracker-paced one,
``use_builtin``), prints ``CALIBRATION <json>``, then ``READY`` and waits for a line on stdin (the test moves
the simulated subject's gaze meanwhile), records for SECONDS and prints one ``SAMPLE <json>`` line per
sample event with its gaze in Open Gaze screen fractions (converted back from ioHub's display
coordinates; ``time`` is the event's device_time, the tracker's own TIME field in s), then ``DONE``.
"""

import json
import sys

from iohub_launch import session  # beside this script


def calibrate(tracker) -> None:
    print("CALIBRATION " + json.dumps(tracker.runSetupProcedure()), flush=True)


def sample(e, to_fraction) -> dict | None:
    """A binocular Gazepoint sample: each eye's gaze as screen fractions, pupil sizes (px, mm)."""
    if not type(e).__name__.startswith("GazepointSampleEvent"):
        return None
    gaze = {eye: to_fraction(getattr(e, f"{eye}_gaze_x"), getattr(e, f"{eye}_gaze_y")) for eye in ("left", "right")}
    return {"time": e.device_time, "status": e.status, "gaze": gaze,
            "pupil_px": [e.left_pupil_measure1, e.right_pupil_measure1],
            "pupil_mm": [e.left_pupil_measure2, e.right_pupil_measure2]}


def main() -> int:
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    config = {"eyetracker.hw.gazepoint.gp3.EyeTracker": {
        "name": "tracker", "device_timer": {"interval": 0.005},
        "network_settings": {"ip_address": "127.0.0.1", "port": port},
        "calibration": {"use_builtin": True, "target_duration": 0.6, "target_delay": 0.3}}}
    return session(config, calibrate, sample, seconds)


if __name__ == "__main__":
    sys.exit(main())
