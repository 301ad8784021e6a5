"""Run in PsychoPy's own environment (not the project's): ioHub with psychopy-eyetracker-pupil-labs, unmodified.

    python iohub_pupil.py PORT SECONDS SURFACE

Configures the Pupil Core eye tracker in gaze mode (``pupillometry_only`` off: it subscribes to ``gaze.3d.``
and ``surfaces.SURFACE``) on Pupil Remote at 127.0.0.1:PORT, runs ``runSetupProcedure`` (Pupil Capture's
calibration: ``C`` and the calibration notifications) and prints ``CALIBRATION <result code>`` and the
ioHub constant it should equal (``OK <EYETRACKER_OK>``), then ``READY`` and waits for a line on stdin (the
test shows the subject a target meanwhile), records for SECONDS and prints one ``SAMPLE <json>`` line per
sample event with its gaze in screen fractions (top-left origin; converted back from ioHub's display
coordinates; ``time`` is the event's device_time, the gaze datum's Pupil time in s), then ``DONE``.
"""

import json
import sys
import time

from iohub_launch import SCREEN_PX, launch  # beside this script
from psychopy import monitors, visual
from psychopy.iohub.constants import EyeTrackerConstants


def main() -> int:
    port, seconds, surface = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
    config = {"eyetracker.hw.pupil_labs.pupil_core.EyeTracker": {
        "name": "tracker", "device_timer": {"interval": 0.005},
        "runtime_settings": {
            "pupil_remote": {"ip_address": "127.0.0.1", "port": port, "timeout_ms": 1000},
            "pupil_capture_recording": {"enabled": False, "location": None},
            "pupillometry_only": False, "confidence_threshold": 0.6, "surface_name": surface}}}
    monitor = monitors.Monitor("eyehil", width=37.7, distance=65.0)  # cm, the guestrin2006 scene's screen
    monitor.setSizePix(list(SCREEN_PX))
    window = visual.Window(SCREEN_PX, fullscr=True, units="pix", monitor=monitor, allowGUI=False)
    config["window"] = window
    io = launch(config)
    try:
        tracker = io.devices.tracker
        print(f"CALIBRATION {tracker.runSetupProcedure()}", flush=True)
        print(f"OK {EyeTrackerConstants.EYETRACKER_OK}", flush=True)
        left, top, right, bottom = io.devices.display.getCoordBounds()
        print("READY", flush=True)
        sys.stdin.readline()
        tracker.setRecordingState(True)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for e in tracker.getEvents():
                kind = type(e).__name__
                if "SampleEvent" not in kind:
                    continue
                x, y = (e.left_gaze_x, e.left_gaze_y) if kind.startswith("Binocular") else (e.gaze_x, e.gaze_y)
                frac = [(x - left) / (right - left), 1.0 - (y - bottom) / (top - bottom)]
                print("SAMPLE " + json.dumps({"time": e.device_time, "kind": kind, "gaze": frac}), flush=True)
            time.sleep(0.01)
        tracker.setRecordingState(False)
    finally:
        io.quit()
        window.close()
    print("DONE", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
