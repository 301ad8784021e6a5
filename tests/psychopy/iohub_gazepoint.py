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
import time

from iohub_launch import SCREEN_PX, launch  # beside this script
from psychopy import monitors, visual


def main() -> int:
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    config = {"eyetracker.hw.gazepoint.gp3.EyeTracker": {
        "name": "tracker", "device_timer": {"interval": 0.005},
        "network_settings": {"ip_address": "127.0.0.1", "port": port},
        "calibration": {"use_builtin": True, "target_duration": 0.6, "target_delay": 0.3}}}
    monitor = monitors.Monitor("eyehil", width=37.7, distance=65.0)  # cm, the guestrin2006 scene's screen
    monitor.setSizePix(list(SCREEN_PX))
    window = visual.Window(SCREEN_PX, fullscr=True, units="pix", monitor=monitor, allowGUI=False)
    config["window"] = window
    io = launch(config)
    try:
        tracker = io.devices.tracker
        result = tracker.runSetupProcedure()
        print("CALIBRATION " + json.dumps(result), flush=True)
        left, top, right, bottom = io.devices.display.getCoordBounds()
        print("READY", flush=True)
        sys.stdin.readline()
        tracker.setRecordingState(True)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for e in tracker.getEvents():
                if not type(e).__name__.startswith("GazepointSampleEvent"):
                    continue
                frac = {}
                for eye in ("left", "right"):
                    x, y = getattr(e, f"{eye}_gaze_x"), getattr(e, f"{eye}_gaze_y")
                    frac[eye] = [(x - left) / (right - left), 1.0 - (y - bottom) / (top - bottom)]
                print("SAMPLE " + json.dumps({"time": e.device_time, "status": e.status, "gaze": frac,
                                              "pupil_px": [e.left_pupil_measure1, e.right_pupil_measure1],
                                              "pupil_mm": [e.left_pupil_measure2, e.right_pupil_measure2]}),
                      flush=True)
            time.sleep(0.01)
        tracker.setRecordingState(False)
    finally:
        io.quit()
        window.close()
    print("DONE", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
