"""The host: open a tracker by URL, talk the native protocol, calibrate gaze, record; never imports the emulator.

- `client`: `open_tracker(url)` -> `Tracker` (handshake, configure, start/stop, samples, STIMULUS, clock sync);
- `links`: URL schemes -> serial-like links (device path, socket://, loop://, spy://, usbip://), and
  `links.fault` (a fault-injecting wrapper: drop, duplicate, corrupt, delay, reorder, disconnect; ``--fault``);
- `wire`: the receive path (`Sample`, `HostStats`: sequence gaps, CRC errors, ...); `errors`: the exception tree;
- `calibration` (through the device), `features` (samples -> estimator arrays), `setup_file` (the tracker's
  geometry file), `recording` (docs/recording.md), `cli` (eyehil info / stream / calibrate / record);
- `gaze/`: the estimators (pure numerics); `detect/`: features from camera frames with OpenCV;
  `frames`: the frames-only mode (FRAME_CHUNKs -> images -> detected samples);
- `urlhandlers/`: the same links as pyserial URL handlers (``eyehil+loop://`` ...).
- `view/`: the live web view (`eyehil view`; optional extra `view`), a host like any other.
"""

from __future__ import annotations

from typing import Any

__all__ = ["Tracker", "open_tracker"]


def __getattr__(name: str) -> Any:
    """`Tracker` and `open_tracker`, imported on first use (so that `eyehil info --help` does not load numpy)."""
    if name in __all__:
        from eyehil.drivers import client

        return getattr(client, name)
    raise AttributeError(f"module 'eyehil.drivers' has no attribute {name!r}")
