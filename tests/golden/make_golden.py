"""Golden test vectors of the eyehil native protocol and the ISCAN mode: one .hex file per message type.

Run once from the repository root, and again only when the wire format is changed on purpose
(then bump the protocol version and say so in docs/protocol.md)::

    python -m tests.golden.make_golden

Each file holds the wire bytes (COBS-encoded frame plus its 0x00 delimiter) as whitespace-separated hex;
lines starting with '#' are comments (the message, seq, timestamp and the frame before COBS, for a
firmware author checking an implementation by hand). tests/test_protocol_native.py re-encodes
`CANONICAL` and compares byte for byte, and decodes each file back to its message.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eyehil.protocols import (
    Ack,
    Capability,
    Configure,
    DeviceInfo,
    DeviceState,
    ErrorCode,
    ErrorReply,
    Eye,
    EyeFeatures,
    EyeSelect,
    Features,
    FrameChunk,
    GetInfo,
    GetStatus,
    Glint,
    GlintFlags,
    Message,
    MessageType,
    Ping,
    PixelFormat,
    Pong,
    PupilFlags,
    Start,
    Status,
    Stimulus,
    StimulusFlags,
    Stop,
    StreamSelect,
    encode,
    encode_raw,
)
from eyehil.protocols.iscan import encode_samples

HERE = Path(__file__).resolve().parent
_RIGHT = EyeFeatures(
    Eye.RIGHT, PupilFlags.DETECTED, 312.25, 241.5, 38.75, 36.5, 12.5, 0.9375,
    (Glint(0, 305.125, 250.0, GlintFlags.VALID), Glint(1, 321.0, 250.25, GlintFlags.VALID | GlintFlags.SATURATED)),
)  # fmt: skip
_INFO = DeviceInfo(
    1, 1, 640, 480, 30, 2000, 250, 2,
    Capability.FEATURES | Capability.FRAMES | Capability.BINOCULAR | Capability.ROI | Capability.TIME_SYNC
    | Capability.STIMULUS | Capability.ISCAN, 4096, "eyehil virtual tracker", "0.1.0",
)  # fmt: skip

# name -> (message, seq, timestamp_us); one entry per MessageType.
CANONICAL: dict[str, tuple[Message, int, int]] = {
    "ping": (Ping(0xC0FFEE), 0, 1_000_000),
    "get_info": (GetInfo(), 1, 1_000_250),
    "configure": (Configure(2, 500, EyeSelect.BOTH, StreamSelect.BOTH, 64, 48, 512, 384), 2, 1_000_500),
    "start": (Start(), 3, 1_000_750),
    "stop": (Stop(), 4, 1_001_000),
    "get_status": (GetStatus(), 5, 1_001_250),
    "stimulus": (Stimulus(17, 265.5, 149.25, StimulusFlags.VISIBLE), 6, 1_001_500),
    "pong": (Pong(0xC0FFEE, 1_000_000, 52_000_123), 0, 52_000_200),
    "device_info": (_INFO, 1, 52_000_400),
    "status": (Status(DeviceState.STREAMING, 7, 4096, 4000, 12, 3, 1, 2, 5, 0, 1, 0, 1, 2), 4095, 60_000_000),
    "features": (Features(1234, (_RIGHT,)), 4096, 60_004_000),
    "frame_chunk": (
        FrameChunk(1234, Eye.RIGHT, PixelFormat.MONO8, 8, 4, 300, 220, 1, 2, 16, bytes(range(0, 160, 10))),
        4097,
        60_004_000,
    ),
    "ack": (Ack(2, MessageType.CONFIGURE), 2, 52_000_600),
    "error": (ErrorReply(ErrorCode.BUSY, 9, MessageType.CONFIGURE, "CONFIGURE while streaming"), 3, 52_000_800),
}
ISCAN_VALUES = np.array([[312.25, 241.5, 305.125, 250.0], [np.nan, np.nan, 0.0, 7000.0]])


def hex_lines(data: bytes, per_line: int = 16, prefix: str = "") -> list[str]:
    """`data` as lines of space-separated hex bytes."""
    return [prefix + data[i : i + per_line].hex(" ") for i in range(0, len(data), per_line)]


def render(name: str) -> str:
    """The text of the golden file for `CANONICAL[name]`."""
    message, seq, timestamp_us = CANONICAL[name]
    raw, wire = encode_raw(message, seq, timestamp_us), encode(message, seq, timestamp_us)
    lines = [
        f"# eyehil native protocol v1 test vector: {message.TYPE.name} (0x{message.TYPE:02X})",
        f"# {message!r}",
        f"# seq={seq} timestamp_us={timestamp_us}",
        f"# frame before COBS ({len(raw)} bytes):",
        *hex_lines(raw, prefix="#   "),
        f"# wire: COBS + 0x00 delimiter ({len(wire)} bytes):",
        *hex_lines(wire),
    ]
    return "\n".join(lines) + "\n"


def render_iscan() -> str:
    """The text of the ISCAN golden file (two records of the default four outputs)."""
    lines = ["# ISCAN mode test vector: two records (pupil H, pupil V, CR H, CR V), px values:"]
    lines += [f"#   {row.tolist()}" for row in ISCAN_VALUES]
    return "\n".join([*lines, *hex_lines(encode_samples(ISCAN_VALUES))]) + "\n"


def main() -> None:
    """Write every golden file next to this script."""
    for name in CANONICAL:
        (HERE / f"{name}.hex").write_text(render(name), encoding="utf-8")
    (HERE / "iscan.hex").write_text(render_iscan(), encoding="utf-8")
    print(f"wrote {len(CANONICAL) + 1} files to {HERE}")


if __name__ == "__main__":
    main()
