"""The eyehil native protocol: encode a message to wire bytes, decode a frame to (header, message).

    wire = encode(Configure(leds=2, rate_hz=500), seq=7, timestamp_us=123)      # ready to write
    header, message = decode(frame)                  # frame: one item FrameDecoder.feed returned

``decode`` raises the `eyehil.protocols.errors` tree (`ProtocolError` and subclasses); a device answers the
ones with an ``error_code`` using `error_reply_for`. Message classes: `MESSAGE_CLASSES`. The
device-side rules for CONFIGURE (ranges, defaults) are here too, as pure functions, so that every
device implementation refuses the same things with the same codes. Specification: docs/protocol.md.
"""

from __future__ import annotations

from eyehil.protocols import cobs
from eyehil.protocols.enums import Capability, EyeSelect, StreamSelect
from eyehil.protocols.errors import ErrorCode, MalformedPayloadError, ProtocolError, UnknownMessageTypeError
from eyehil.protocols.header import SUPPORTED_VERSIONS, Header, MessageType, pack_frame, unpack_frame, wire_frame
from eyehil.protocols.messages import Configure, GetInfo, GetStatus, Ping, Start, Stimulus, Stop, truncate_utf8
from eyehil.protocols.replies import Ack, DeviceInfo, ErrorReply, Pong, Status
from eyehil.protocols.samples import Features, FrameChunk

Message = (
    Ping | GetInfo | Configure | Start | Stop | GetStatus | Stimulus
    | Pong | DeviceInfo | Status | Features | FrameChunk | Ack | ErrorReply
)  # fmt: skip
MESSAGE_CLASSES: dict[MessageType, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        Ping, GetInfo, Configure, Start, Stop, GetStatus, Stimulus,
        Pong, DeviceInfo, Status, Features, FrameChunk, Ack, ErrorReply,
    )
}  # fmt: skip
MIN_RATE_HZ = 30
MAX_RATE_HZ = 2000


def encode_raw(message: Message, seq: int, timestamp_us: int) -> bytes:
    """Header + payload + CRC of `message` (before COBS); raise `ValueError` if a field does not fit."""
    return pack_frame(message.TYPE, seq, timestamp_us, message.to_payload())


def encode(message: Message, seq: int, timestamp_us: int) -> bytes:
    """Wire bytes of `message`: COBS-encoded frame followed by the 0x00 delimiter."""
    return wire_frame(message.TYPE, seq, timestamp_us, message.to_payload())


def decode(
    frame: bytes, accept: frozenset[MessageType] | None = None, versions: frozenset[int] = SUPPORTED_VERSIONS
) -> tuple[Header, Message]:
    """Decode one COBS-decoded frame into its header and message.

    `accept` restricts the types this side takes (a device passes `HOST_TYPES`); others raise
    `UnknownMessageTypeError`. Payload errors raise `MalformedPayloadError` with the frame's seq and type.
    """
    header, payload = unpack_frame(frame, versions)
    return header, decode_payload(header, payload, accept)


def decode_payload(header: Header, payload: bytes, accept: frozenset[MessageType] | None = None) -> Message:
    """The message of a checked frame's `header` and `payload` (the second step of `decode`, with its errors)."""
    cls = MESSAGE_CLASSES.get(header.msg_type)  # type: ignore[call-overload]
    if cls is None or (accept is not None and header.msg_type not in accept):
        raise UnknownMessageTypeError(f"message type 0x{header.msg_type:02X}", header.seq, header.msg_type)
    try:
        return cls.from_payload(payload)
    except ValueError as exc:
        raise MalformedPayloadError(f"{cls.TYPE.name}: {exc}", header.seq, header.msg_type) from exc


def decode_wire(wire: bytes, accept: frozenset[MessageType] | None = None) -> tuple[Header, Message]:
    """Decode exactly one COBS frame, with or without its trailing delimiter (tests, tools)."""
    return decode(cobs.decode(wire.removesuffix(b"\x00")), accept)


HOST_TYPES = frozenset(t for t in MessageType if t.from_host)
DEVICE_TYPES = frozenset(t for t in MessageType if not t.from_host)


def error_reply_for(exc: ProtocolError) -> ErrorReply | None:
    """The ERROR a device sends for a decoding error, or None when it must stay silent (no trusted seq)."""
    if exc.error_code is None or exc.seq is None:
        return None
    return ErrorReply(exc.error_code, exc.seq, exc.msg_type or 0, truncate_utf8(str(exc)))


def default_configure(info: DeviceInfo) -> Configure:
    """The configuration a device uses when START comes before any CONFIGURE.

    All LEDs, the device's default rate, both eyes if binocular (else the right eye), features only
    (frames if the device cannot stream features), full sensor.
    """
    binocular = Capability.BINOCULAR in info.capabilities
    stream = StreamSelect.FEATURES if Capability.FEATURES in info.capabilities else StreamSelect.FRAMES
    eyes = EyeSelect.BOTH if binocular else EyeSelect.RIGHT
    return Configure(info.led_count, info.sample_rate_hz, eyes, stream)


def check_configure(cfg: Configure, info: DeviceInfo) -> tuple[ErrorCode, str] | None:
    """Why a device refuses `cfg` (ERROR code and text), or None if it accepts it."""
    caps = info.capabilities
    checks = (
        (cfg.leds not in (1, 2) or cfg.leds > info.led_count, ErrorCode.INVALID_ARGUMENT, "LED count"),
        (not _rate_ok(cfg.rate_hz, info), ErrorCode.INVALID_ARGUMENT, "rate"),
        (cfg.eyes not in (EyeSelect.RIGHT, EyeSelect.LEFT, EyeSelect.BOTH), ErrorCode.INVALID_ARGUMENT, "eyes"),
        (cfg.stream not in (StreamSelect.FEATURES, StreamSelect.FRAMES, StreamSelect.BOTH),
         ErrorCode.INVALID_ARGUMENT, "stream"),
        (cfg.eyes == EyeSelect.BOTH and Capability.BINOCULAR not in caps, ErrorCode.UNSUPPORTED, "binocular"),
        (StreamSelect.FEATURES in cfg.stream and Capability.FEATURES not in caps, ErrorCode.UNSUPPORTED, "features"),
        (StreamSelect.FRAMES in cfg.stream and Capability.FRAMES not in caps, ErrorCode.UNSUPPORTED, "frames"),
        (_roi_set(cfg) and Capability.ROI not in caps, ErrorCode.UNSUPPORTED, "region of interest"),
        (not _roi_fits(cfg, info), ErrorCode.INVALID_ARGUMENT, "region of interest"),
    )  # fmt: skip
    for failed, code, what in checks:
        if failed:
            return code, f"CONFIGURE: {what} not accepted"
    return None


def _rate_ok(rate_hz: int, info: DeviceInfo) -> bool:
    """True if the rate is inside both the protocol's and the device's range."""
    return max(MIN_RATE_HZ, info.min_rate_hz) <= rate_hz <= min(MAX_RATE_HZ, info.max_rate_hz)


def _roi_set(cfg: Configure) -> bool:
    """True if `cfg` asks for a region smaller than the full sensor."""
    return (cfg.roi_x, cfg.roi_y, cfg.roi_w, cfg.roi_h) != (0, 0, 0, 0)


def _roi_fits(cfg: Configure, info: DeviceInfo) -> bool:
    """True if the region is the full-sensor code (w = h = 0, x = y = 0) or a non-empty sensor subset."""
    if cfg.roi_w == 0 and cfg.roi_h == 0:
        return cfg.roi_x == 0 and cfg.roi_y == 0
    inside_x = cfg.roi_w > 0 and cfg.roi_x + cfg.roi_w <= info.camera_width
    return inside_x and cfg.roi_h > 0 and cfg.roi_y + cfg.roi_h <= info.camera_height
