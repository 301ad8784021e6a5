"""Enumerations and flag sets carried in eyehil native messages (all numbers are wire values).

Flag sets are `IntFlag` with the default KEEP boundary: bits a newer sender sets and this version does
not name survive decoding. Senders set reserved bits to 0; receivers ignore the ones they do not know.
"""

from __future__ import annotations

from enum import IntEnum, IntFlag


class Eye(IntEnum):
    """Which eye a FEATURES record or a FRAME_CHUNK shows (uint8). BOTH only in FRAME_CHUNK."""

    RIGHT = 0
    LEFT = 1
    BOTH = 2


class EyeSelect(IntFlag):
    """CONFIGURE's choice of eyes (uint8 bit set): bit Eye.RIGHT and bit Eye.LEFT."""

    RIGHT = 1 << Eye.RIGHT
    LEFT = 1 << Eye.LEFT
    BOTH = RIGHT | LEFT


class StreamSelect(IntFlag):
    """CONFIGURE's choice of what to stream while started (uint8 bit set)."""

    FEATURES = 0x01
    FRAMES = 0x02
    BOTH = FEATURES | FRAMES


class Capability(IntFlag):
    """DEVICE_INFO capability bits (uint16)."""

    FEATURES = 0x0001  # streams FEATURES
    FRAMES = 0x0002  # streams FRAME_CHUNK
    BINOCULAR = 0x0004  # can report both eyes
    ROI = 0x0008  # honours CONFIGURE's region of interest
    TIME_SYNC = 0x0010  # answers PING with PONG
    STIMULUS = 0x0020  # emulator only: accepts STIMULUS (a simulated subject is attached)
    ISCAN = 0x0040  # also speaks the ISCAN-compatible legacy mode


class PupilFlags(IntFlag):
    """Validity of one eye's pupil record in FEATURES (uint8)."""

    DETECTED = 0x01  # a pupil was found; the ellipse fields are meaningful
    PARTIAL = 0x02  # the pupil outline is partly hidden (eyelid, image border)
    CLIPPED = 0x04  # the pupil touches the region-of-interest border
    BLINK = 0x08  # the eye is closed or closing


class GlintFlags(IntFlag):
    """Validity of one glint in FEATURES (uint8)."""

    VALID = 0x01  # found; x and y are meaningful
    SATURATED = 0x02  # its centre is at sensor saturation (centroid less precise)
    ON_PUPIL_EDGE = 0x04  # overlaps the pupil boundary (both features may be biased)
    AMBIGUOUS = 0x08  # the LED assignment is uncertain


class PixelFormat(IntEnum):
    """Pixel encoding of FRAME_CHUNK data (uint8); rows top to bottom, pixels left to right."""

    MONO8 = 1
    MONO16 = 2  # uint16 little-endian

    @property
    def bytes_per_pixel(self) -> int:
        """Bytes one pixel occupies."""
        return 1 if self is PixelFormat.MONO8 else 2


class DeviceState(IntEnum):
    """The device's state machine, reported in STATUS (uint8)."""

    IDLE = 0
    STREAMING = 1


class StimulusFlags(IntFlag):
    """STIMULUS flags (uint8)."""

    VISIBLE = 0x01  # the target is shown and the simulated subject fixates it; 0 hides it
