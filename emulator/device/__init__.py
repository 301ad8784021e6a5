"""The virtual eye tracker: a device core free of transports, the simulated subject, and the device side of links.

- `tracker.VirtualTracker` (native protocol) and `iscan.IscanTracker` (ISCAN legacy mode): bytes in
  (`feed`), bytes out (`poll`, `read_available`), no I/O, no threads;
- `subject.Subject`, `gaze` (scripts: fixations, saccades, pursuits, blinks), `solver` (exact and
  interpolated features from `emulator.forward`), `camera` (exposures, detection flags), `clock`;
- `stimulus`: the STIMULUS side channel, the emulator's stand-in for the screen (one coordinate conversion);
- links: `links` (the `DeviceLink` and `DeviceCore` interfaces, `LinkRunner`), `pty_link`, `tcp_link`,
  `loop` (in-process, for tests), `usbip_server` (USB/IP);
- `build` (a device from named options), `setup_file` (the host's geometry file), `cli` (`eyehil
  emulate`), `pytest_plugin` (a fixture serving an emulator on a pseudo-terminal).

Import from the submodules (this package imports nothing, so that `emulator.device.pytest_plugin`
stays cheap to load in every pytest session).
"""
