"""The pipe from the facade to its LSL outlet process (pure codec): length-prefixed msgpack messages.

A message is a 4-byte little-endian length and that many bytes of msgpack (at most `MAX_MESSAGE`). The first
message describes the stream (`stream_message`), every later one a chunk of samples (`chunk_message`: float64
rows, C order, and one LSL timestamp per row, s). The process answers once, on its stdout, with one JSON line
(`ready_line`): its pid and what it listens on.
"""

from __future__ import annotations

import json
import struct
from typing import BinaryIO

import msgpack
import numpy as np

MAX_MESSAGE = 16 << 20  # bytes: far above a block (a 1 kHz device's block is about 10 kB)
_HEADER = struct.Struct("<I")


class WireError(ValueError):
    """A message that is not one of this codec's."""


def frame(message: dict) -> bytes:
    """One message on the pipe."""
    body = msgpack.packb(message, use_bin_type=True)
    if len(body) > MAX_MESSAGE:
        raise WireError(f"message of {len(body)} bytes > {MAX_MESSAGE}")
    return _HEADER.pack(len(body)) + body


def read(stream: BinaryIO) -> dict | None:
    """The next message from `stream`; None at its end."""
    header = stream.read(_HEADER.size)
    if not header:
        return None
    if len(header) < _HEADER.size:
        raise WireError("the pipe ended inside a message header")
    (size,) = _HEADER.unpack(header)
    if size > MAX_MESSAGE:
        raise WireError(f"message of {size} bytes > {MAX_MESSAGE}")
    body = stream.read(size)
    if len(body) < size:
        raise WireError("the pipe ended inside a message")
    message = msgpack.unpackb(body, raw=False)
    if not isinstance(message, dict):
        raise WireError(f"a message is a map, not {type(message).__name__}")
    return message


def chunk_message(rows: np.ndarray, stamps: np.ndarray) -> dict:
    """Samples (N, C) and their timestamps (N,) as a message."""
    rows = np.ascontiguousarray(rows, dtype="<f8")
    stamps = np.ascontiguousarray(stamps, dtype="<f8")
    if rows.ndim != 2 or stamps.shape != (rows.shape[0],):
        raise WireError(f"rows {rows.shape} and stamps {stamps.shape} do not match")
    return {"rows": rows.tobytes(), "channels": rows.shape[1], "stamps": stamps.tobytes()}


def chunk_arrays(message: dict, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows (N, `channels`) and timestamps (N,) of a chunk message."""
    try:
        rows = np.frombuffer(message["rows"], dtype="<f8")
        stamps = np.frombuffer(message["stamps"], dtype="<f8")
    except (KeyError, TypeError, ValueError) as exc:
        raise WireError(f"not a chunk: {exc}") from exc
    if message.get("channels") != channels or rows.size != stamps.size * channels:
        raise WireError(f"a chunk of {rows.size} values, {stamps.size} stamps for {channels} channels")
    return rows.reshape(stamps.size, channels), stamps


def ready_line(pid: int, listening: list[str], beyond_loopback: list[str], moved: int | None) -> str:
    """The process's one answer: its pid, its listening sockets, those of them reachable from other machines,
    the binds the loopback library moved (None: the library is not loaded)."""
    return json.dumps({"pid": pid, "listening": listening, "beyond_loopback": beyond_loopback, "moved": moved}) + "\n"
