"""The virtual eye tracker: a device core free of transports, the simulated subject, and the device side of links.

- `tracker.VirtualTracker` (native protocol) and `iscan.IscanTracker` (ISCAN legacy mode): bytes in
  (`feed`), bytes out (`poll`, `read_available`), no I/O, no threads;
- `subject.Subject`, `gaze` (scripts: fixations, saccades, pursuits, blinks), `solver` (exact and
  interpolated features from `eyehil.emulator.forward`), `appearance` (the outlines a renderer needs), `camera`
  (exposures, detection flags), `clock`; `frames` and `frame_stream` (rendered images as FRAME_CHUNKs);
- `stimulus`: the STIMULUS side channel, the emulator's stand-in for the screen (one coordinate conversion);
- links: `links` (the `DeviceLink` and `DeviceCore` interfaces, `LinkRunner`), `pty_link`, `tcp_link`,
  `loop` (in-process, for tests), `usbip_link` over `usbip_server` / `usbip_session` / `usbip_control` (USB/IP);
- the Pupil Core Network API facade `zmq_server.PupilServer` (`zmq_remote`, `zmq_backbone`, `zmq_core`,
  `zmq_capture`, `zmq_calibration`, `zmq_datums`, `zmq_gaze`, `zmq_frames`) and `lsl_outlet`;
- `build` (a device from named options), `setup_file` (the host's geometry file), `cli` (`eyehil
  emulate`), `pytest_plugin` (a fixture serving an emulator on a pseudo-terminal).

Import from the submodules (this package imports nothing, so that `eyehil.emulator.device.pytest_plugin`
stays cheap to load in every pytest session).
"""
