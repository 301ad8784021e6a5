"""The host: open a tracker by URL, talk the native protocol, calibrate gaze, record; never imports the emulator.

- `client`: `open_tracker(url)` -> `Tracker` (handshake, configure, start/stop, samples, STIMULUS, clock sync);
- `links`: URL schemes -> serial-like links (device path, socket://, loop://, spy://, usbip://);
- `wire`: the receive path (`Sample`, `HostStats`: sequence gaps, CRC errors, ...); `errors`: the exception tree;
- `calibration` (through the device), `features` (samples -> estimator arrays), `setup_file` (the tracker's
  geometry file), `recording` (docs/recording.md), `cli` (eyehil info / stream / calibrate / record);
- `gaze`: the estimators (pure numerics); `detect` (+ `detect_ellipse`, `detect_glints`): features from
  camera frames with OpenCV; `frames`: the frames-only mode (FRAME_CHUNKs -> images -> detected samples).
"""

from eyehil.drivers.client import Tracker, open_tracker

__all__ = ["Tracker", "open_tracker"]
