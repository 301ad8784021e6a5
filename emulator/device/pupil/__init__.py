"""The Pupil Capture facade: the virtual tracker on the Pupil Core Network API (ZeroMQ), for unmodified clients.

- `server`: `PupilServer`, which starts and stops the parts below;
- `remote`: Pupil Remote (REQ/REP commands); `backbone`: the IPC backbone (XSUB/XPUB proxy);
- `core`: the device thread (exposures -> datums, notifications -> actions);
- `capture`: what Pupil Capture does with backbone messages (no sockets, no threads);
- `calibration`: screen-marker calibration with the host estimators as gazers;
- `datums`: Pupil time and the `pupil.<id>.2d` / `glint.<id>` datums; `gaze`: gaze datums;
- `eye3d`: the 3-D eye model (`pupil.<id>.3d`, the 3-D parts of `gaze.3d.*`) from the simulated eyes;
- `frames`: `frame.eye.<id>` images rendered on their own thread; `world`: `frame.world`, the screen with the
  current target;
- `recorder`: recording folders (`R`): Pupil's PLData files of the pupil, gaze, notification and annotation datums.
"""
