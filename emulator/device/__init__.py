"""The virtual eye tracker: a device core free of transports, the simulated subject, and its facades.

- `tracker.VirtualTracker` (native protocol) and `iscan.IscanTracker` (ISCAN legacy mode): bytes in
  (`feed`), bytes out (`poll`, `read_available`), no I/O, no threads;
- `subject.Subject`, `gaze` (scripts: fixations, saccades, pursuits, blinks), `solver` (exact and
  interpolated features from `eyehil.emulator.forward`; `SolveQueue`: coalesced solves off the
  device thread), `solve_process` (those solves in a worker process, off the device's GIL), `appearance`
  (the outlines a renderer needs), `camera`
  (exposures, detection flags), `clock`; `frames` and `frame_stream` (rendered images as FRAME_CHUNKs),
  `render_pool` (images rendered off the device's thread: worker processes or threads);
- `stimulus`: the STIMULUS side channel, the emulator's stand-in for the screen (one coordinate conversion);
- `links/`: the device side of pty, TCP, USB/IP and the in-process loop;
- `pupil/`: the Pupil Capture facade (ZeroMQ Pupil Core Network API); `lsl/`: its LSL outlet (a process of
  its own, kept on the loopback);
- `opengaze/`: the Gazepoint Open Gaze API facade (XML over TCP, port 4242);
- `firmware_sensor`: the camera behind the C firmware's host HAL (firmware_stubs/);
- `build` (a device from named options), `setup_file` (the host's geometry file), `cli` (`eyehil
  emulate`), `pytest_plugin` (a fixture serving an emulator on a pseudo-terminal).

Import from the submodules (this package imports nothing, so that `eyehil.emulator.device.pytest_plugin`
stays cheap to load in every pytest session).
"""
