"""ISCAN-compatible legacy mode (ISCAN ETL/RK series serial output), so host code written for it runs.

Host -> device: single bytes, 0x80 start streaming, 0x81 stop; any other byte is ignored.
Device -> host, one record per sample, little-endian uint16 words, no checksum::

    0x4444, output_1, ..., output_K

The outputs are a configured selection, in order, of pupil H, pupil V, corneal reflection H, corneal
reflection V (image px, x right, y down), each sent as round(px * 10) (ties to even) clipped to
0..65535; a missing value (NaN, e.g. pupil lost) is sent as 0. Both ends must agree on K out of band.
The host parser locks on the header word at the record period: a 0x44 0x44 pair counts as a header only
if another follows one record later. Data words equal to 0x4444 (1747.6 px) at the record period could
still fool it; they need a sensor over 1747 px wide. Specification: docs/protocol.md, section 13.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import IntEnum

import numpy as np

HEADER_WORD = 0x4444
HEADER_BYTES = HEADER_WORD.to_bytes(2, "little")
SCALE = 10  # wire units per pixel
WORD_MAX = 0xFFFF


class IscanCommand(IntEnum):
    """Command bytes the host sends."""

    START = 0x80
    STOP = 0x81


class IscanOutput(IntEnum):
    """Values a record can carry; a configuration is a sequence of these."""

    PUPIL_H = 0
    PUPIL_V = 1
    CR_H = 2
    CR_V = 3


DEFAULT_OUTPUTS = (IscanOutput.PUPIL_H, IscanOutput.PUPIL_V, IscanOutput.CR_H, IscanOutput.CR_V)


def parse_commands(data: bytes | bytearray | memoryview) -> list[IscanCommand]:
    """Device side: the START/STOP commands in `data`, in order; other bytes are ignored."""
    return [IscanCommand(b) for b in bytes(data) if b in (IscanCommand.START, IscanCommand.STOP)]


def select_outputs(
    pupil_xy: np.ndarray, cr_xy: np.ndarray, outputs: Sequence[IscanOutput] = DEFAULT_OUTPUTS
) -> np.ndarray:
    """Device side: values [N, K] (px) for `outputs`, from pupil and corneal-reflection centres [N, 2]."""
    table = np.concatenate([np.asarray(pupil_xy, float), np.asarray(cr_xy, float)], axis=-1)
    return table[..., [int(o) for o in outputs]]


def to_words(values_px: np.ndarray) -> np.ndarray:
    """Wire words of pixel values: round(px * 10) clipped to 0..65535; NaN -> 0."""
    scaled = np.rint(np.asarray(values_px, dtype=float) * SCALE)
    return np.clip(np.nan_to_num(scaled, nan=0.0), 0, WORD_MAX).astype("<u2")


def encode_samples(values_px: np.ndarray) -> bytes:
    """Device side: records of N samples [N, K] (px) as one byte string."""
    words = to_words(np.atleast_2d(values_px))
    header = np.full((words.shape[0], 1), HEADER_WORD, dtype="<u2")
    return np.concatenate([header, words], axis=1).tobytes()


def encode_sample(values_px: Sequence[float]) -> bytes:
    """Device side: the record of one sample (K values, px)."""
    return encode_samples(np.asarray(values_px, dtype=float)[None, :])


class IscanParser:
    """Host side: incremental parser of the record stream; resynchronises on the header word.

    ``feed`` returns the complete records as an array [M, K] of pixels (words / 10). Without a checksum,
    a record that lost bytes is only noticed when the next header is not where it should be: by default
    that record has been returned already (no added latency); with ``confirm=True`` a record is returned
    only once the next header is seen in place (one sample of latency) and a damaged one is dropped.
    Counters: ``samples``, ``resyncs`` (lock lost), ``dropped`` (records dropped unconfirmed),
    ``bytes_discarded``.
    """

    def __init__(self, n_outputs: int = len(DEFAULT_OUTPUTS), confirm: bool = False) -> None:
        """Parse records of `n_outputs` data words; `confirm` trades one sample of latency for integrity."""
        self.n_outputs = n_outputs
        self.confirm = confirm
        self.stride = 2 * (n_outputs + 1)
        self._buf = bytearray()
        self._locked = False
        self.samples = 0
        self.resyncs = 0
        self.dropped = 0
        self.bytes_discarded = 0

    def feed(self, data: bytes | bytearray | memoryview) -> np.ndarray:
        """Consume bytes; return the records completed, [M, K] pixels."""
        self._buf += data
        records: list[bytes] = []
        pos = 0
        while (step := self._step(pos)) is not None:
            pos, record = step
            if record is not None:
                records.append(record)
        del self._buf[:pos]
        self.samples += len(records)
        words = np.frombuffer(b"".join(records), dtype="<u2").reshape(-1, self.n_outputs + 1)
        return words[:, 1:] / SCALE

    def _step(self, pos: int) -> tuple[int, bytes | None] | None:
        """Advance from `pos`: (new position, record or None), or None when more bytes are needed."""
        buf, stride = self._buf, self.stride
        if self._locked:
            need = stride + 2 if self.confirm else stride
            if len(buf) < pos + need:
                return None
            next_ok = not self.confirm or buf[pos + stride : pos + stride + 2] == HEADER_BYTES
            if buf[pos : pos + 2] == HEADER_BYTES and next_ok:
                return pos + stride, bytes(buf[pos : pos + stride])
            self._locked = False
            self.resyncs += 1
            if buf[pos : pos + 2] == HEADER_BYTES:  # header fine, successor missing: drop this record
                self.dropped += 1
                self.bytes_discarded += 2
                return pos + 2, None
        return self._search(pos)

    def _search(self, pos: int) -> tuple[int, None] | None:
        """Unlocked: find a header confirmed by the next one; discard what precedes it."""
        buf, stride = self._buf, self.stride
        found = buf.find(HEADER_BYTES, pos)
        if found < 0:
            keep = max(pos, len(buf) - 1)  # the last byte may be half a header
            self.bytes_discarded += keep - pos
            return None if keep == pos else (keep, None)
        self.bytes_discarded += found - pos
        if len(buf) < found + stride + 2:
            return None if found == pos else (found, None)
        if buf[found + stride : found + stride + 2] == HEADER_BYTES:
            self._locked = True
            return found, None
        self.bytes_discarded += 1
        return found + 1, None
