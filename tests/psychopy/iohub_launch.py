"""Run in PsychoPy's own environment: what the ioHub scripts (iohub_gazepoint.py, iohub_pupil.py) share.

`SCREEN_PX` is the X server's screen (xvfb-run -s "-screen 0 1920x1080x24"). `session(config, calibrate,
sample, seconds)` opens a full-screen window on the guestrin2006 scene's monitor, starts ioHub's server (tried
again when its process does not answer within ioHub's fixed 30 s: a busy machine), prints ``LAUNCHED``, runs
`calibrate(tracker)`, prints ``READY``, waits for a line on stdin (the test moves the simulated subject's gaze
meanwhile), records for `seconds` and prints ``SAMPLE <json>`` for every event `sample(event, to_fraction)`
turns into a dict, then ``DONE``. `to_fraction(x, y)` converts ioHub's display coordinates to screen fractions
(top-left origin).
"""

import json
import sys
import time

from psychopy import monitors, visual
from psychopy.iohub import launchHubServer

SCREEN_PX = (1920, 1080)


def launch(config: dict, tries: int = 5):
    """launchHubServer(**config), up to `tries` times; prints a ``RETRY`` line for each failed start."""
    for attempt in range(tries):
        try:
            return launchHubServer(**dict(config))
        except RuntimeError as exc:
            print(f"RETRY ioHub did not start ({exc})", flush=True)
            if attempt == tries - 1:
                raise
    return None


def session(config: dict, calibrate, sample, seconds: float) -> int:
    """The run of the module docstring; the script's exit code."""
    monitor = monitors.Monitor("eyehil", width=37.7, distance=65.0)  # cm, the guestrin2006 scene's screen
    monitor.setSizePix(list(SCREEN_PX))
    window = visual.Window(SCREEN_PX, fullscr=True, units="pix", monitor=monitor, allowGUI=False)
    io = launch({**config, "window": window})
    try:
        tracker = io.devices.tracker
        print("LAUNCHED", flush=True)  # where a hang was: before or in the calibration
        calibrate(tracker)
        left, top, right, bottom = io.devices.display.getCoordBounds()

        def to_fraction(x: float, y: float) -> list[float]:
            return [(x - left) / (right - left), 1.0 - (y - bottom) / (top - bottom)]

        print("READY", flush=True)
        sys.stdin.readline()
        tracker.setRecordingState(True)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for event in tracker.getEvents():
                record = sample(event, to_fraction)
                if record is not None:
                    print("SAMPLE " + json.dumps(record), flush=True)
            time.sleep(0.01)  # ioHub's event loop: nothing to wait on but its queue
        tracker.setRecordingState(False)
    finally:
        io.quit()
        window.close()
    print("DONE", flush=True)
    return 0
