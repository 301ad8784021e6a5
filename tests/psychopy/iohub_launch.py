"""Run in PsychoPy's own environment: what the ioHub scripts (iohub_gazepoint.py, iohub_pupil.py) share.

`SCREEN_PX` is the X server's screen (xvfb-run -s "-screen 0 1920x1080x24"); `launch(config)` starts ioHub's
server, trying again when its process does not answer within ioHub's fixed 30 s (a busy machine).
"""

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
