"""Streamed samples of the eyehil native protocol (device -> host): FEATURES and FRAME_CHUNK.

Image coordinates are in pixels of the full sensor, OpenCV convention (origin at the centre of the
top-left pixel, x right, y down), whatever region of interest is configured. A pupil ellipse is given
by its centre, its full axis lengths a >= b and the angle of axis a in degrees from image +x toward
image +y, in [0, 180) (the convention of `eyehil.emulator.optics.ellipse`).

FEATURES payload: ``<IB`` frame id, eye count; per eye ``<BBffffffB`` eye, PupilFlags, centre x, y,
axes a, b, angle, confidence (0..1), glint count; per glint ``<BBff`` LED id, GlintFlags, x, y.
FRAME_CHUNK payload: ``<IBBHHHHHHI`` then the pixel bytes (see `FrameChunk`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar, Self, TypeVar

from eyehil.protocols.enums import Eye, GlintFlags, PixelFormat, PupilFlags
from eyehil.protocols.errors import MalformedPayloadError
from eyehil.protocols.header import MessageType
from eyehil.protocols.messages import field_values

FEATURES_HEAD = struct.Struct("<IB")
EYE_RECORD = struct.Struct("<BBffffffB")
GLINT_RECORD = struct.Struct("<BBff")


@dataclass(frozen=True, slots=True)
class Glint:
    """One corneal reflection: the LED that made it, its centre (px) and validity."""

    led: int
    x: float
    y: float
    flags: GlintFlags = GlintFlags.VALID

    def __post_init__(self) -> None:
        """Coerce the flags."""
        object.__setattr__(self, "flags", GlintFlags(self.flags))


@dataclass(frozen=True, slots=True)
class EyeFeatures:
    """One eye's pupil ellipse (px, degrees), detection confidence (0..1), validity and glints."""

    eye: Eye
    flags: PupilFlags
    centre_x: float
    centre_y: float
    axis_a: float
    axis_b: float
    angle_deg: float
    confidence: float
    glints: tuple[Glint, ...] = ()

    def __post_init__(self) -> None:
        """Coerce the eye (RIGHT or LEFT only), the flags and the glint sequence."""
        if Eye(self.eye) is Eye.BOTH:
            raise ValueError("a FEATURES record describes one eye, not Eye.BOTH")
        object.__setattr__(self, "eye", Eye(self.eye))
        object.__setattr__(self, "flags", PupilFlags(self.flags))
        object.__setattr__(self, "glints", tuple(self.glints))

    @property
    def size(self) -> int:
        """Bytes of this record on the wire."""
        return EYE_RECORD.size + GLINT_RECORD.size * len(self.glints)


@dataclass(frozen=True, slots=True)
class Features:
    """device -> host: one camera sample. The header timestamp is the exposure's mid-time (device us)."""

    TYPE: ClassVar[MessageType] = MessageType.FEATURES
    frame_id: int
    eyes: tuple[EyeFeatures, ...]

    def __post_init__(self) -> None:
        """Store the eye records as a tuple."""
        object.__setattr__(self, "eyes", tuple(self.eyes))

    def to_payload(self) -> bytes:
        """Encode the frame id, the eye count and each eye record with its glints."""
        try:
            parts = [FEATURES_HEAD.pack(self.frame_id, len(self.eyes))]
            for eye in self.eyes:
                parts.append(EYE_RECORD.pack(*field_values(eye)[:-1], len(eye.glints)))
                parts.extend(GLINT_RECORD.pack(g.led, g.flags, g.x, g.y) for g in eye.glints)
        except struct.error as exc:
            raise ValueError(f"Features: {exc}") from exc
        return b"".join(parts)

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode; the records must fill the payload exactly."""
        if len(payload) < FEATURES_HEAD.size:
            raise MalformedPayloadError(f"FEATURES payload of {len(payload)} bytes is too short")
        frame_id, count = FEATURES_HEAD.unpack_from(payload)
        offset, eyes = FEATURES_HEAD.size, []
        for _ in range(count):
            eye, offset = _unpack_eye(payload, offset)
            eyes.append(eye)
        if offset != len(payload):
            raise MalformedPayloadError(f"FEATURES payload has {len(payload) - offset} trailing bytes")
        return cls(frame_id, tuple(eyes))


def _unpack_eye(payload: bytes, offset: int) -> tuple[EyeFeatures, int]:
    """Read one eye record and its glints at `offset`; return it and the offset after it."""
    if offset + EYE_RECORD.size > len(payload):
        raise MalformedPayloadError(f"FEATURES eye record at offset {offset} is truncated")
    *fields, n_glints = EYE_RECORD.unpack_from(payload, offset)
    offset += EYE_RECORD.size
    if offset + n_glints * GLINT_RECORD.size > len(payload):
        raise MalformedPayloadError(f"FEATURES: {n_glints} glints at offset {offset} do not fit")
    glints = []
    for _ in range(n_glints):
        led, flags, x, y = GLINT_RECORD.unpack_from(payload, offset)
        glints.append(Glint(led, x, y, flags))
        offset += GLINT_RECORD.size
    return EyeFeatures(*fields, glints=tuple(glints)), offset


_E = TypeVar("_E", bound=IntEnum)
_EYES: dict[int, Eye] = {int(e): e for e in Eye}
_PIXEL_FORMATS: dict[int, PixelFormat] = {int(f): f for f in PixelFormat}


def _member(enum: type[_E], members: dict[int, _E], value: object) -> _E:
    """``enum(value)`` (raising its ValueError for unknown values), by a dict lookup for the known ones."""
    try:
        return members[value]  # type: ignore[index]
    except (KeyError, TypeError):
        return enum(value)


@dataclass(frozen=True, slots=True)
class FrameChunk:
    """device -> host: a piece of one camera image (the region of interest, or one eye's crop).

    An image of width x height pixels in `pixel_format`, whose top-left pixel is at (roi_x, roi_y) on
    the sensor, is sent as `chunk_count` chunks; chunk `chunk_index` carries bytes [offset, offset +
    len(data)) of the row-major image. All chunks of an image share frame id, eye, geometry and
    header timestamp (the exposure's mid-time), and the frame id matches the FEATURES of that exposure.
    """

    TYPE: ClassVar[MessageType] = MessageType.FRAME_CHUNK
    STRUCT: ClassVar[struct.Struct] = struct.Struct("<IBBHHHHHHI")
    frame_id: int
    eye: Eye
    pixel_format: PixelFormat
    width: int
    height: int
    roi_x: int
    roi_y: int
    chunk_index: int
    chunk_count: int
    offset: int
    data: bytes

    def __post_init__(self) -> None:
        """Coerce the enums and the data; check that the chunk lies inside its image."""
        if type(self.eye) is not Eye:  # (a frozen field costs a slow object.__setattr__: only when it changes)
            object.__setattr__(self, "eye", _member(Eye, _EYES, self.eye))
        if type(self.pixel_format) is not PixelFormat:
            object.__setattr__(self, "pixel_format", _member(PixelFormat, _PIXEL_FORMATS, self.pixel_format))
        if type(self.data) is not bytes:
            object.__setattr__(self, "data", bytes(self.data))
        if not 0 <= self.chunk_index < self.chunk_count:
            raise ValueError(f"chunk index {self.chunk_index} not in 0..{self.chunk_count - 1}")
        if self.offset + len(self.data) > self.image_size:
            raise ValueError(f"chunk bytes [{self.offset}, +{len(self.data)}) exceed the image size")

    @property
    def image_size(self) -> int:
        """Bytes of the whole image."""
        return self.width * self.height * self.pixel_format.bytes_per_pixel

    def to_payload(self) -> bytes:
        """Encode the chunk header then the pixel bytes."""
        try:
            head = self.STRUCT.pack(self.frame_id, self.eye, self.pixel_format, self.width, self.height, self.roi_x,
                                    self.roi_y, self.chunk_index, self.chunk_count, self.offset)
        except struct.error as exc:
            raise ValueError(f"FrameChunk: {exc}") from exc
        return head + self.data

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode; the pixel bytes are the rest of the payload."""
        if len(payload) < cls.STRUCT.size:
            raise MalformedPayloadError(f"FRAME_CHUNK payload of {len(payload)} bytes is too short")
        frame_id, eye, fmt, *rest = cls.STRUCT.unpack_from(payload)
        # the enums looked up here, so that __post_init__ need not replace two frozen fields (slow) per chunk
        return cls(frame_id, _member(Eye, _EYES, eye), _member(PixelFormat, _PIXEL_FORMATS, fmt), *rest,
                   payload[cls.STRUCT.size :])
