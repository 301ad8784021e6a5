"""USB/IP URB messages (CMD_SUBMIT, RET_SUBMIT, CMD_UNLINK, RET_UNLINK): a pure codec, no I/O.

After a successful OP_REQ_IMPORT (see `eyehil.protocols.usbip.messages`) the connection carries these messages until it
closes. Each is a 48-byte big-endian header (a 20-byte basic part, then 28 bytes that depend on the
command), possibly followed by data::

    0 u32 command  4 u32 seqnum  8 u32 devid (busnum << 16 | devnum)  12 u32 direction (0 OUT, 1 IN)
    16 u32 ep (endpoint number 0..15, without the direction bit)
    CMD_SUBMIT 1: 20 u32 transfer_flags  24 s32 transfer_buffer_length  28 s32 start_frame
                  32 s32 number_of_packets  36 s32 interval  40 setup[8] (USB order, little-endian fields);
                  for OUT, transfer_buffer_length bytes of data follow
    RET_SUBMIT 3: 20 s32 status (0 or -errno)  24 s32 actual_length  28 s32 start_frame
                  32 s32 number_of_packets  36 s32 error_count  40 8 zero bytes; for an IN URB,
                  actual_length bytes of data follow (the receiver knows the direction from its request)
    CMD_UNLINK 2: 20 u32 seqnum of the URB to cancel, then 24 zero bytes
    RET_UNLINK 4: 20 s32 status (-ECONNRESET: cancelled; 0: it had already completed), then 24 zero bytes

A reply carries its command's seqnum; devid, direction and ep are 0 in replies (as the Linux device
side sends them). A URB cancelled by CMD_UNLINK gets only the RET_UNLINK, never a RET_SUBMIT.
Known answer: CMD_SUBMIT seqnum 1, devid 0x00010002, IN, ep 0, 18 bytes, setup GET_DESCRIPTOR(device)::

    00000001 00000001 00010002 00000001 00000000  00000000 00000012 00000000 00000000 00000000
    80 06 00 01 00 00 12 00

Isochronous URBs (packet descriptors after the data) are not supported.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import ClassVar

from eyehil.protocols.usbip.messages import UsbipError

URB_HEADER_SIZE = 48
URB_STALL = -32  # -EPIPE: the endpoint stalled (request not supported)
URB_UNLINKED = -104  # -ECONNRESET: the URB was cancelled by CMD_UNLINK
_BASIC = struct.Struct(">IIIII")
_CMD_SUBMIT = struct.Struct(">IiiiI8s")
_RET_SUBMIT = struct.Struct(">iiiii8x")
_CMD_UNLINK = struct.Struct(">I24x")
_RET_UNLINK = struct.Struct(">i24x")


class Command(IntEnum):
    CMD_SUBMIT = 1
    CMD_UNLINK = 2
    RET_SUBMIT = 3
    RET_UNLINK = 4


class Direction(IntEnum):
    OUT = 0
    IN = 1


@dataclass(frozen=True)
class CmdSubmit:
    """Submit one URB; `data` is the OUT payload (empty for IN)."""

    seqnum: int
    devid: int
    direction: int
    ep: int
    transfer_buffer_length: int
    setup: bytes = bytes(8)
    transfer_flags: int = 0
    start_frame: int = 0
    number_of_packets: int = 0
    interval: int = 0
    data: bytes = b""
    command: ClassVar[Command] = Command.CMD_SUBMIT

    @property
    def data_length(self) -> int:
        """How many data bytes follow this header on the wire."""
        return self.transfer_buffer_length if self.direction == Direction.OUT else 0

    def encode(self) -> bytes:
        if len(self.data) != self.data_length or len(self.setup) != 8:
            raise ValueError("CMD_SUBMIT: OUT data must fill transfer_buffer_length, IN has none; setup is 8 bytes")
        tail = _CMD_SUBMIT.pack(self.transfer_flags, self.transfer_buffer_length, self.start_frame,
                                self.number_of_packets, self.interval, self.setup)
        return _basic(self, self.devid, self.direction, self.ep) + tail + self.data


@dataclass(frozen=True)
class RetSubmit:
    """Completion of a URB; `data` is the IN payload (empty for OUT)."""

    seqnum: int
    status: int
    actual_length: int
    data: bytes = b""
    start_frame: int = 0
    number_of_packets: int = 0
    error_count: int = 0
    devid: int = 0
    direction: int = 0
    ep: int = 0
    command: ClassVar[Command] = Command.RET_SUBMIT

    def encode(self) -> bytes:
        if self.data and len(self.data) != self.actual_length:
            raise ValueError("RET_SUBMIT: data must be empty (OUT) or actual_length bytes (IN)")
        tail = _RET_SUBMIT.pack(self.status, self.actual_length, self.start_frame, self.number_of_packets,
                                self.error_count)
        return _basic(self, self.devid, self.direction, self.ep) + tail + self.data


@dataclass(frozen=True)
class CmdUnlink:
    """Cancel the pending URB whose CMD_SUBMIT had `unlink_seqnum`."""

    seqnum: int
    devid: int
    unlink_seqnum: int
    direction: int = 0
    ep: int = 0
    command: ClassVar[Command] = Command.CMD_UNLINK

    def encode(self) -> bytes:
        return _basic(self, self.devid, self.direction, self.ep) + _CMD_UNLINK.pack(self.unlink_seqnum)


@dataclass(frozen=True)
class RetUnlink:
    """Answer to CMD_UNLINK: `URB_UNLINKED` if the URB was cancelled, 0 if it had already completed."""

    seqnum: int
    status: int
    devid: int = 0
    direction: int = 0
    ep: int = 0
    command: ClassVar[Command] = Command.RET_UNLINK

    def encode(self) -> bytes:
        return _basic(self, self.devid, self.direction, self.ep) + _RET_UNLINK.pack(self.status)


UrbMessage = CmdSubmit | RetSubmit | CmdUnlink | RetUnlink


def _basic(message: UrbMessage, devid: int, direction: int, ep: int) -> bytes:
    return _BASIC.pack(message.command, message.seqnum, devid, direction, ep)


def decode_urb_header(header: bytes) -> UrbMessage:
    """Decode a 48-byte URB header; the message's `data` is empty (read it with `data_to_read`)."""
    if len(header) != URB_HEADER_SIZE:
        raise UsbipError(f"URB header: expected {URB_HEADER_SIZE} bytes, got {len(header)}")
    command, seqnum, devid, direction, ep = _BASIC.unpack_from(header)
    if direction not in (Direction.OUT, Direction.IN) or ep > 15:
        raise UsbipError(f"URB header: direction {direction} / endpoint {ep} out of range")
    base = {"seqnum": seqnum, "devid": devid, "direction": direction, "ep": ep}
    if command == Command.CMD_SUBMIT:
        flags, length, start, packets, interval, setup = _CMD_SUBMIT.unpack_from(header, _BASIC.size)
        message: UrbMessage = CmdSubmit(**base, transfer_buffer_length=length, setup=setup, transfer_flags=flags,
                                        start_frame=start, number_of_packets=packets, interval=interval)
    elif command == Command.RET_SUBMIT:
        status, actual, start, packets, errors = _RET_SUBMIT.unpack_from(header, _BASIC.size)
        message = RetSubmit(**base, status=status, actual_length=actual, start_frame=start,
                            number_of_packets=packets, error_count=errors)
    elif command == Command.CMD_UNLINK:
        message = CmdUnlink(**base, unlink_seqnum=_CMD_UNLINK.unpack_from(header, _BASIC.size)[0])
    elif command == Command.RET_UNLINK:
        message = RetUnlink(**base, status=_RET_UNLINK.unpack_from(header, _BASIC.size)[0])
    else:
        raise UsbipError(f"URB header: unknown command 0x{command:08X}")
    _check_lengths(message)
    return message


def _check_lengths(message: UrbMessage) -> None:
    if isinstance(message, CmdSubmit) and message.transfer_buffer_length < 0:
        raise UsbipError(f"CMD_SUBMIT: negative transfer_buffer_length {message.transfer_buffer_length}")
    if isinstance(message, RetSubmit) and message.actual_length < 0:
        raise UsbipError(f"RET_SUBMIT: negative actual_length {message.actual_length}")


def data_to_read(message: UrbMessage, request_direction: int | None = None) -> int:
    """Bytes of data after this header: a CMD_SUBMIT OUT's payload, or an IN RET_SUBMIT's (the direction of
    a RET_SUBMIT is that of its request, which only the receiver knows: pass it as `request_direction`)."""
    if isinstance(message, CmdSubmit):
        return message.data_length
    if isinstance(message, RetSubmit) and request_direction == Direction.IN:
        return message.actual_length
    return 0


def with_data(message: CmdSubmit | RetSubmit, data: bytes) -> CmdSubmit | RetSubmit:
    """The message with the data read after its header attached."""
    return replace(message, data=bytes(data))
