"""eyehil: a hardware-in-the-loop emulator of a remote video eye tracker.

The package (each subpackage's docstring names its modules; README.md has the commands):

- `eyehil.emulator`: the simulated subject and device (anatomy, optics, forward model, frames, the virtual
  tracker, its links and facades); knows nothing of hosts;
- `eyehil.protocols`: pure codecs of the links (native protocol, ISCAN, Pupil, USB/IP);
- `eyehil.drivers`: the host (open a tracker by URL, detect features in frames, calibrate gaze);
- `eyehil.analysis`: the replication study and the discrepancy workflow;
- `parallel`: chunks of eyes on a local process pool or a Dask cluster (simulate, the study, the discrepancy
  workflow);
- `stopping`: a command's wait for SIGTERM or Ctrl-C, in slices (the signal may land on another thread);
- `cbuild`: a C source of the package built into a shared library on first use, cached (the framing's kernels,
  the renderer's noise kernel, the LSL outlet's loopback bind);
- `cli`: the `eyehil` command (a thin dispatcher; `__main__`: ``python -m eyehil``); `emulate_view`: the
  live view beside the device for `eyehil emulate --view` (the one place the two meet outside analysis).

The public API a script needs, importable from here (each name is loaded on first use, so that
``import eyehil`` stays cheap):

- `open_tracker(url)` -> `Tracker`: a host's connection to a tracker, real or emulated (`eyehil.drivers`);
- `DeviceOptions`, `build_device(options)`: a virtual tracker core, bytes in and out (`eyehil.emulator.device`);
- `load_scene(name_or_path)`, `eyes_from_spec(spec)`, `simulate(eyes, scene, targets)`: the forward model;
- `run_study(eyes)`: the replication study (`eyehil.analysis.study`).

Opening ``eyehil+loop://``, ``eyehil+socket://`` ... URLs with plain `serial.serial_for_url` works once eyehil is
imported (and in every pytest session, through the eyehil plugin): see `eyehil.drivers.urlhandlers`.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:
    __version__ = version("eyehil")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

_API: dict[str, str] = {
    "open_tracker": "eyehil.drivers.client",
    "Tracker": "eyehil.drivers.client",
    "DeviceOptions": "eyehil.emulator.device.build",
    "build_device": "eyehil.emulator.device.build",
    "load_scene": "eyehil.emulator.scene",
    "eyes_from_spec": "eyehil.emulator.eye.select",
    "simulate": "eyehil.emulator.forward",
    "run_study": "eyehil.analysis.study.replication",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'eyehil' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


def _register_url_handlers() -> None:
    """Let pyserial's `serial_for_url` open eyehil's schemes (handlers: `eyehil.drivers.urlhandlers`)."""
    try:
        import serial
    except ImportError:  # pyserial is a dependency; a broken environment should still import eyehil
        return
    if "eyehil.drivers.urlhandlers" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("eyehil.drivers.urlhandlers")


_register_url_handlers()
