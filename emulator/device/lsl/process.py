"""The LSL outlet process: `python -m eyehil.emulator.device.lsl.process`, started by `outlet.GazeOutlet`.

liblsl runs here, apart from the facade, so that the loopback bind library (`loopback`) can be preloaded into
this process alone. Reads `wire` messages on stdin: the stream description, then chunks of samples with their
timestamps, pushed as they come; answers once on stdout (`wire.ready_line`) when the outlet is open; ends at the
end of stdin. EYEHIL_LSL_LOOPBACK=0 in its environment: liblsl as LSLAPICFG or its defaults say, not the
loopback configuration. Its errors go to stderr with a non-zero exit status.
"""

from __future__ import annotations

import os
import sys

from eyehil.emulator.device.lsl import wire
from eyehil.emulator.device.lsl.library import load_pylsl
from eyehil.emulator.device.lsl.loopback import moved_binds
from eyehil.emulator.device.lsl.sockets import listening


def open_outlet(pylsl, stream: dict):
    """A pylsl outlet for the stream description of the first message."""
    info = pylsl.StreamInfo(name=str(stream["name"]), type=str(stream["type"]),
                            channel_count=len(stream["channels"]), nominal_srate=float(stream["rate_hz"]),
                            channel_format=pylsl.cf_double64, source_id=str(stream["source_id"]))
    desc = info.desc()
    for key in ("manufacturer", "model"):
        desc.append_child_value(key, str(stream[key]))
    xml = desc.append_child("channels")
    for channel in stream["channels"]:
        node = xml.append_child("channel")
        for key, value in channel.items():
            node.append_child_value(str(key), str(value))
    return pylsl.StreamOutlet(info)


def main() -> int:
    """Serve one outlet until stdin ends."""
    stdin = sys.stdin.buffer
    first = wire.read(stdin)
    if first is None or "stream" not in first:
        print("lsl outlet process: the first message must describe the stream", file=sys.stderr)
        return 2
    stream = first["stream"]
    pylsl = load_pylsl(loopback=os.environ.get("EYEHIL_LSL_LOOPBACK", "1") == "1")
    outlet = open_outlet(pylsl, stream)
    try:
        bound = listening()
    except OSError:  # not Linux
        bound = []
    sys.stdout.write(wire.ready_line(os.getpid(), [str(b) for b in bound], [str(b) for b in bound if not b.loopback],
                                     moved_binds()))
    sys.stdout.flush()
    channels = len(stream["channels"])
    while (message := wire.read(stdin)) is not None:
        rows, stamps = wire.chunk_arrays(message, channels)
        outlet.push_chunk(rows, stamps.tolist())
    del outlet
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
