"""Vectorised FEATURES codec: N samples with the same eyes and glint count, packed with numpy.

A FEATURES frame with a fixed number of eyes E and glints per eye G has a fixed layout, so a numpy
structured dtype (`features_dtype`) describes the whole frame (header, payload, CRC) byte for byte.
`encode_features_batch` fills N such records at once and returns the N wire frames, identical to
`native.encode(Features(...))` of each sample; `decode_features_batch` is the inverse for frames of one
shape. Arrays: N samples, E eyes, G glints; coordinates px, angles degrees (see `eyehil.protocols.samples`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eyehil.protocols.crc import crc16
from eyehil.protocols.errors import BadLengthError, BadMagicError, CrcError, MalformedPayloadError
from eyehil.protocols.framing import encode_frame
from eyehil.protocols.header import MAGIC, MIN_FRAME_SIZE, PROTOCOL_VERSION, SEQ_MODULUS, MessageType

_GLINT = np.dtype([("led", "u1"), ("flags", "u1"), ("x", "<f4"), ("y", "<f4")])
_PUPIL = [("eye", "u1"), ("flags", "u1")] + [
    (name, "<f4") for name in ("centre_x", "centre_y", "axis_a", "axis_b", "angle_deg", "confidence")
]
_HEADER = [("magic", "<u2"), ("version", "u1"), ("type", "u1"), ("seq", "<u4"), ("timestamp_us", "<u8")]


def features_dtype(n_eyes: int, n_glints: int) -> np.dtype:
    """Packed dtype of a whole FEATURES frame (before COBS) with `n_eyes` eyes of `n_glints` glints."""
    eye = np.dtype([*_PUPIL, ("n_glints", "u1"), ("glints", _GLINT, (n_glints,))])
    body = [*_HEADER, ("payload_len", "<u2"), ("frame_id", "<u4"), ("n_eyes", "u1"), ("eyes", eye, (n_eyes,))]
    return np.dtype([*body, ("crc", "<u2")])


@dataclass(frozen=True)
class FeaturesBatch:
    """N FEATURES samples of E eyes with G glints each; shapes in brackets."""

    frame_id: np.ndarray  # [N] uint32
    eye: np.ndarray  # [E] Eye values, the same for every sample
    flags: np.ndarray  # [N, E] PupilFlags
    centre: np.ndarray  # [N, E, 2] px
    axes: np.ndarray  # [N, E, 2] full lengths a, b, px
    angle_deg: np.ndarray  # [N, E]
    confidence: np.ndarray  # [N, E] 0..1
    glint_led: np.ndarray  # [N, E, G] LED ids
    glint_xy: np.ndarray  # [N, E, G, 2] px
    glint_flags: np.ndarray  # [N, E, G] GlintFlags

    @property
    def shape(self) -> tuple[int, int, int]:
        """(N, E, G)."""
        return self.glint_led.shape  # type: ignore[return-value]


def _fill_eyes(eyes: np.ndarray, b: FeaturesBatch) -> None:
    """Write the per-eye and per-glint fields of `b` into the record array `eyes` [N, E]."""
    eyes["eye"] = b.eye
    eyes["flags"] = b.flags
    eyes["centre_x"], eyes["centre_y"] = b.centre[..., 0], b.centre[..., 1]
    eyes["axis_a"], eyes["axis_b"] = b.axes[..., 0], b.axes[..., 1]
    eyes["angle_deg"], eyes["confidence"] = b.angle_deg, b.confidence
    eyes["n_glints"] = b.glint_led.shape[-1]
    glints = eyes["glints"]
    glints["led"], glints["flags"] = b.glint_led, b.glint_flags
    glints["x"], glints["y"] = b.glint_xy[..., 0], b.glint_xy[..., 1]


def pack_features_batch(batch: FeaturesBatch, seq0: int, timestamps_us: np.ndarray) -> np.ndarray:
    """Structured array [N] of whole frames: sequence numbers seq0, seq0 + 1, ...; CRCs filled in."""
    n, n_eyes, n_glints = batch.shape
    rec = np.zeros(n, features_dtype(n_eyes, n_glints))
    rec["magic"], rec["version"], rec["type"] = MAGIC, PROTOCOL_VERSION, MessageType.FEATURES
    rec["seq"] = (seq0 + np.arange(n, dtype=np.uint64)) % SEQ_MODULUS
    rec["timestamp_us"] = timestamps_us
    rec["payload_len"] = rec.dtype.itemsize - MIN_FRAME_SIZE
    rec["frame_id"], rec["n_eyes"] = batch.frame_id, n_eyes
    _fill_eyes(rec["eyes"], batch)
    rows = rec.view(np.uint8).reshape(n, -1)
    rec["crc"] = [crc16(row[:-2].tobytes()) for row in rows]
    return rec


def encode_features_batch(batch: FeaturesBatch, seq0: int, timestamps_us: np.ndarray) -> list[bytes]:
    """The N wire frames (COBS + delimiter) of `batch`, one per sample."""
    rec = pack_features_batch(batch, seq0, timestamps_us)
    return [encode_frame(row.tobytes()) for row in rec.view(np.uint8).reshape(len(rec), -1)]


def unpack_features_batch(frames: Sequence[bytes], n_eyes: int, n_glints: int) -> np.ndarray:
    """Check N decoded FEATURES frames of one shape; return them as a structured array [N].

    Raises `BadLengthError` if a frame does not have the shape's size, `CrcError`, `BadMagicError`, or
    `MalformedPayloadError` if a frame is not FEATURES, or its eye/glint counts or eye ids differ.
    """
    dtype = features_dtype(n_eyes, n_glints)
    for i, frame in enumerate(frames):
        if len(frame) != dtype.itemsize:
            raise BadLengthError(f"frame {i}: {len(frame)} bytes, shape ({n_eyes}, {n_glints}) has {dtype.itemsize}")
    rec = np.frombuffer(b"".join(frames), dtype)
    for i, frame in enumerate(frames):
        if crc16(frame[:-2]) != rec["crc"][i]:
            raise CrcError(crc16(frame[:-2]), int(rec["crc"][i]))
    if np.any(rec["magic"] != MAGIC):
        raise BadMagicError("a frame does not start with the eyehil magic")
    same = (rec["type"] == MessageType.FEATURES) & (rec["n_eyes"] == n_eyes)
    same &= np.all(rec["eyes"]["n_glints"] == n_glints, axis=-1) & (rec["version"] == PROTOCOL_VERSION)
    same &= np.all(rec["eyes"]["eye"] == rec["eyes"]["eye"][:1], axis=-1)
    if not np.all(same):
        raise MalformedPayloadError(f"frame {int(np.argmin(same))} is not a FEATURES frame of this shape")
    return rec


def decode_features_batch(frames: Sequence[bytes], n_eyes: int, n_glints: int) -> FeaturesBatch:
    """Inverse of `encode_features_batch` for decoded (COBS-free) frames of one shape and eye order."""
    rec = unpack_features_batch(frames, n_eyes, n_glints)
    eyes, glints = rec["eyes"], rec["eyes"]["glints"]
    return FeaturesBatch(
        frame_id=rec["frame_id"].copy(),
        eye=eyes["eye"][0].copy() if len(rec) else np.zeros(n_eyes, np.uint8),
        flags=eyes["flags"].copy(),
        centre=np.stack([eyes["centre_x"], eyes["centre_y"]], axis=-1),
        axes=np.stack([eyes["axis_a"], eyes["axis_b"]], axis=-1),
        angle_deg=eyes["angle_deg"].copy(),
        confidence=eyes["confidence"].copy(),
        glint_led=glints["led"].copy(),
        glint_xy=np.stack([glints["x"], glints["y"]], axis=-1),
        glint_flags=glints["flags"].copy(),
    )
