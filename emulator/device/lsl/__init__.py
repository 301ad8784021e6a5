"""The Lab Streaming Layer outlet of type ``Gaze`` beside the ZeroMQ facade (optional: pylsl, the extra ``lsl``).

- `outlet`: `GazeOutlet`, the facade's side (samples, LSL times, the stable source id); it starts
- `process`: the outlet process, which owns liblsl, fed through `wire` (length-prefixed msgpack on a pipe);
- `channels`: the stream's channels and rows (eyehil's layout, or Pupil Capture's LSL relay);
- `library`: pylsl and liblsl's loopback configuration (discovery on 127.0.0.1);
- `loopback` and `loopback_bind.c`: the library preloaded into the outlet process that keeps liblsl's data and
  time ports on 127.0.0.1 (liblsl cannot be told to);
- `sockets`: what a process listens on, from /proc.

Import from the submodules.
"""
