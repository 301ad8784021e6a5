"""Pure codecs of the links a host uses to talk to the (virtual) eye tracker: no I/O, no threads.

- `cobs`, `crc`, `framing`: COBS frames delimited by 0x00 and an incremental, never-raising decoder;
  `kernels`: the same CRC and COBS compiled (`kernels.c`, built once per machine on first import; the one
  exception to "no I/O"), used by `crc`, `cobs` and `header.wire_frame` where they can be had;
- `header`, `messages`, `replies`, `samples`, `native`: the eyehil native protocol (docs/protocol.md);
- `stream`: bytes in, decoded messages, faults, counters and sequence gaps out;
- `batch`: vectorised FEATURES encoding/decoding with numpy; `images`: FRAME_CHUNK split/reassembly;
- `iscan`: the ISCAN-compatible legacy mode; `pupil`: the Pupil Core Network API (ZeroMQ payloads);
- `opengaze`: the Gazepoint Open Gaze API (XML records, docs/opengaze.md);
- `usbip/`: USB/IP messages, URBs and the CDC-ACM device's descriptors;
- `address`: TCP port numbers as every command checks them;
- `enums`: the protocol's enumerations and flags;
- `errors`: the exception tree (drawn in its docstring) and the ERROR codes.
"""

from eyehil.protocols.enums import (
    Capability,
    DeviceState,
    Eye,
    EyeSelect,
    GlintFlags,
    PixelFormat,
    PupilFlags,
    StimulusFlags,
    StreamSelect,
)
from eyehil.protocols.errors import (
    BadLengthError,
    BadMagicError,
    CobsDecodeError,
    CrcError,
    ErrorCode,
    FramingError,
    MalformedPayloadError,
    ProtocolError,
    UnknownMessageTypeError,
    UnsupportedVersionError,
)
from eyehil.protocols.framing import FrameDecoder, FramingFault, encode_frame
from eyehil.protocols.header import PROTOCOL_VERSION, Header, MessageType, seq_gap
from eyehil.protocols.messages import Configure, GetInfo, GetStatus, Ping, Start, Stimulus, Stop
from eyehil.protocols.native import (
    DEVICE_TYPES,
    HOST_TYPES,
    MESSAGE_CLASSES,
    Message,
    check_configure,
    decode,
    decode_wire,
    default_configure,
    encode,
    encode_raw,
    error_reply_for,
)
from eyehil.protocols.replies import Ack, DeviceInfo, ErrorReply, Pong, Status
from eyehil.protocols.samples import EyeFeatures, Features, FrameChunk, Glint
from eyehil.protocols.stream import ChunkRun, NativeReceiver, Received, Rejected

__all__ = [
    "DEVICE_TYPES",
    "HOST_TYPES",
    "MESSAGE_CLASSES",
    "PROTOCOL_VERSION",
    "Ack",
    "BadLengthError",
    "BadMagicError",
    "Capability",
    "ChunkRun",
    "CobsDecodeError",
    "Configure",
    "CrcError",
    "DeviceInfo",
    "DeviceState",
    "ErrorCode",
    "ErrorReply",
    "Eye",
    "EyeFeatures",
    "EyeSelect",
    "Features",
    "FrameChunk",
    "FrameDecoder",
    "FramingError",
    "FramingFault",
    "GetInfo",
    "GetStatus",
    "Glint",
    "GlintFlags",
    "Header",
    "MalformedPayloadError",
    "Message",
    "MessageType",
    "NativeReceiver",
    "Ping",
    "PixelFormat",
    "Pong",
    "ProtocolError",
    "PupilFlags",
    "Received",
    "Rejected",
    "Start",
    "Status",
    "Stimulus",
    "StimulusFlags",
    "Stop",
    "StreamSelect",
    "UnknownMessageTypeError",
    "UnsupportedVersionError",
    "check_configure",
    "decode",
    "decode_wire",
    "default_configure",
    "encode",
    "encode_frame",
    "encode_raw",
    "error_reply_for",
    "seq_gap",
]
