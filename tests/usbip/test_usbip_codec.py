"""USB/IP codec: known-answer byte layouts written from the protocol definition, and round trips."""

from __future__ import annotations

import struct

import pytest

from eyehil.protocols.usbip.messages import (
    USB_DEVICE,
    OpCode,
    OpHeader,
    OpStatus,
    UsbipError,
    cdc_acm_device,
    decode_busid,
    decode_devlist_reply,
    encode_devlist_reply,
    encode_import_reply,
    encode_import_request,
)
from eyehil.protocols.usbip.urb import (
    URB_UNLINKED,
    CmdSubmit,
    CmdUnlink,
    Direction,
    RetSubmit,
    RetUnlink,
    data_to_read,
    decode_urb_header,
    with_data,
)

GET_DEVICE_DESCRIPTOR = bytes.fromhex("8006000100001200")


def test_op_headers_known_answers() -> None:
    assert OpHeader(OpCode.REQ_DEVLIST).encode() == bytes.fromhex("0111 8005 00000000")
    assert OpHeader(OpCode.REP_IMPORT, OpStatus.DEV_BUSY).encode() == bytes.fromhex("0111 0003 00000002")
    assert encode_import_request("1-1") == bytes.fromhex("0111 8003 00000000") + b"1-1" + bytes(29)
    assert OpHeader.decode(bytes.fromhex("0111 0005 00000000")) == OpHeader(OpCode.REP_DEVLIST)


def test_usb_device_record_layout() -> None:
    record = cdc_acm_device("1-1", busnum=1, devnum=2).encode()
    assert len(record) == USB_DEVICE.size == 312
    assert record[:256].rstrip(b"\0") == b"/sys/devices/platform/eyehil/usb1/1-1"
    assert record[256:288] == b"1-1" + bytes(29)
    # busnum, devnum, speed (3 = high), VID, PID, bcdDevice, class 02/00/00, config 0, 1 config, 2 interfaces
    assert record[288:] == bytes.fromhex("00000001 00000002 00000003 1209 0001 0100 02 00 00 00 01 02")


def test_devlist_reply_layout_and_round_trip() -> None:
    device = cdc_acm_device()
    reply = encode_devlist_reply([device])
    assert reply[:12] == bytes.fromhex("0111 0005 00000000 00000001")
    assert len(reply) == 12 + 312 + 2 * 4
    assert reply[-8:] == bytes.fromhex("02020000 0a000000")  # CDC ACM interface, CDC data interface
    assert decode_devlist_reply(reply) == [device]
    assert decode_devlist_reply(encode_devlist_reply([])) == []


def test_devlist_reply_rejects_truncation_and_failure() -> None:
    reply = encode_devlist_reply([cdc_acm_device()])
    with pytest.raises(UsbipError):
        decode_devlist_reply(reply[:-1])
    with pytest.raises(UsbipError):
        decode_devlist_reply(OpHeader(OpCode.REP_DEVLIST, OpStatus.ERROR).encode() + bytes(4))


def test_import_reply_carries_the_device_only_on_success() -> None:
    device = cdc_acm_device()
    assert encode_import_reply(device) == bytes.fromhex("0111 0003 00000000") + device.encode()
    assert encode_import_reply(None, OpStatus.NODEV) == bytes.fromhex("0111 0003 00000004")
    assert decode_busid(encode_import_request("2-1.4")[8:]) == "2-1.4"
    with pytest.raises(ValueError):
        encode_import_request("x" * 32)


def test_cmd_submit_known_answer() -> None:
    urb = CmdSubmit(seqnum=1, devid=0x00010002, direction=Direction.IN, ep=0, transfer_buffer_length=18,
                    setup=GET_DEVICE_DESCRIPTOR)
    assert urb.encode() == bytes.fromhex(
        "00000001 00000001 00010002 00000001 00000000"
        "00000000 00000012 00000000 00000000 00000000" "8006000100001200")


def test_cmd_submit_out_carries_its_data() -> None:
    urb = CmdSubmit(7, 0x00010002, Direction.OUT, 2, 3, data=b"abc")
    wire = urb.encode()
    assert wire[:20] == bytes.fromhex("00000001 00000007 00010002 00000000 00000002")
    assert wire[24:28] == bytes.fromhex("00000003") and wire[48:] == b"abc"


def test_ret_submit_and_unlink_known_answers() -> None:
    ret = RetSubmit(seqnum=1, status=0, actual_length=2, data=b"\x12\x01")
    assert ret.encode() == bytes.fromhex("00000003 00000001 00000000 00000000 00000000"
                                         "00000000 00000002 00000000 00000000 00000000 0000000000000000" "1201")
    assert RetSubmit(9, -32, 0).encode()[20:24] == bytes.fromhex("ffffffe0")  # -EPIPE
    unlink = CmdUnlink(seqnum=5, devid=0x00010002, unlink_seqnum=3)
    assert unlink.encode() == bytes.fromhex("00000002 00000005 00010002 00000000 00000000 00000003") + bytes(24)
    cancelled = bytes.fromhex("00000004 00000005 00000000 00000000 00000000 ffffff98") + bytes(24)  # -ECONNRESET
    assert RetUnlink(5, URB_UNLINKED).encode() == cancelled


@pytest.mark.parametrize("message", [
    CmdSubmit(1, 0x10002, Direction.IN, 0, 64, setup=GET_DEVICE_DESCRIPTOR),
    CmdSubmit(0xFFFFFFFF, 0x10002, Direction.OUT, 2, 5, data=b"hello", transfer_flags=0x40, interval=4),
    CmdSubmit(3, 0x10002, Direction.IN, 2, 65536),
    RetSubmit(3, 0, 4, data=b"data"),
    RetSubmit(4, -104, 0, start_frame=-1, number_of_packets=0, error_count=2),
    CmdUnlink(5, 0x10002, 3, Direction.IN, 2),
    RetUnlink(5, URB_UNLINKED),
    RetUnlink(6, 0),
])
def test_urb_round_trip(message: CmdSubmit | RetSubmit | CmdUnlink | RetUnlink) -> None:
    wire = message.encode()
    decoded = decode_urb_header(wire[:48])
    direction = Direction.IN if isinstance(message, RetSubmit) and message.data else None
    n = data_to_read(decoded, direction)
    assert n == len(wire) - 48
    if isinstance(decoded, CmdSubmit | RetSubmit):
        decoded = with_data(decoded, wire[48:])
    assert decoded == message


@pytest.mark.parametrize("header", [
    struct.pack(">5I", 9, 1, 0, 0, 0) + bytes(28),  # unknown command
    struct.pack(">5I", 1, 1, 0, 2, 0) + bytes(28),  # direction 2
    struct.pack(">5I", 1, 1, 0, 0, 16) + bytes(28),  # endpoint 16
    struct.pack(">6Ii", 1, 1, 0, 0, 2, 0, -1) + bytes(20),  # negative transfer_buffer_length
    struct.pack(">5I", 1, 1, 0, 0, 0) + bytes(27),  # short
])
def test_malformed_urb_headers_raise(header: bytes) -> None:
    with pytest.raises(UsbipError):
        decode_urb_header(header)


def test_encoders_refuse_inconsistent_lengths() -> None:
    with pytest.raises(ValueError):
        CmdSubmit(1, 0, Direction.OUT, 2, 4, data=b"abc").encode()
    with pytest.raises(ValueError):
        CmdSubmit(1, 0, Direction.IN, 2, 4, data=b"abcd").encode()
    with pytest.raises(ValueError):
        RetSubmit(1, 0, 4, data=b"abc").encode()
