"""URB-level behaviour of the server, byte for byte: control transfers, pending IN URBs, unlink, stalls."""

from __future__ import annotations

from usbip_helpers import Collector, RawHost

from eyehil.emulator.device.links.usbip.server import UsbipCdcServer
from eyehil.protocols.usbip.descriptors import device_descriptor
from eyehil.protocols.usbip.messages import OpStatus
from eyehil.protocols.usbip.urb import URB_STALL, URB_UNLINKED, CmdSubmit, CmdUnlink, Direction, RetSubmit, RetUnlink

DEVID = 0x00010002
IN, OUT = Direction.IN, Direction.OUT


def submit(raw: RawHost, seqnum: int, ep: int, direction: int, length: int = 0, data: bytes = b"",
           setup: bytes = bytes(8)) -> None:
    length = len(data) if direction == OUT else length
    raw.sock.sendall(CmdSubmit(seqnum, DEVID, direction, ep, length, setup, data=data).encode())


def test_control_get_descriptor_and_stall(raw: RawHost) -> None:
    assert raw.import_device().status == OpStatus.OK
    submit(raw, 1, 0, IN, 64, setup=bytes.fromhex("8006000100004000"))
    assert raw.reply(in_direction=True) == RetSubmit(1, 0, 18, device_descriptor())
    submit(raw, 2, 0, IN, 4, setup=bytes.fromhex("c001000000000400"))  # vendor request: stall
    assert raw.reply() == RetSubmit(2, URB_STALL, 0)


def test_control_out_with_data_stage(server: UsbipCdcServer, raw: RawHost) -> None:
    raw.import_device()
    submit(raw, 1, 0, OUT, data=bytes.fromhex("80250000000008"), setup=bytes.fromhex("2120000000000700"))
    assert raw.reply() == RetSubmit(1, 0, 7)
    assert server.line_coding.baudrate == 9600


def test_bulk_out_and_unknown_endpoint(collector: Collector, raw: RawHost) -> None:
    raw.import_device()
    submit(raw, 1, 2, OUT, data=b"ping")
    assert raw.reply() == RetSubmit(1, 0, 4)
    assert collector.data == b"ping"
    submit(raw, 2, 5, IN, 64)
    assert raw.reply() == RetSubmit(2, URB_STALL, 0)


def test_pending_in_urb_completes_when_data_arrives(server: UsbipCdcServer, raw: RawHost) -> None:
    raw.import_device()
    submit(raw, 1, 2, IN, 4)
    submit(raw, 2, 2, IN, 512)
    server.send(b"abcdefgh")
    assert raw.reply(in_direction=True) == RetSubmit(1, 0, 4, b"abcd")  # capped at transfer_buffer_length
    assert raw.reply(in_direction=True) == RetSubmit(2, 0, 4, b"efgh")


def test_unlink_of_a_pending_in_urb(server: UsbipCdcServer, raw: RawHost) -> None:
    raw.import_device()
    submit(raw, 1, 2, IN, 64)
    submit(raw, 2, 1, IN, 16)  # notification endpoint: stays pending
    raw.sock.sendall(CmdUnlink(3, DEVID, 1).encode())
    assert raw.reply() == RetUnlink(3, URB_UNLINKED)
    raw.sock.sendall(CmdUnlink(4, DEVID, 2).encode())
    assert raw.reply() == RetUnlink(4, URB_UNLINKED)
    submit(raw, 5, 2, IN, 64)
    server.send(b"after")
    assert raw.reply(in_direction=True) == RetSubmit(5, 0, 5, b"after")  # the cancelled URB got nothing


def test_unlink_of_a_completed_urb_answers_zero(server: UsbipCdcServer, raw: RawHost) -> None:
    raw.import_device()
    server.send(b"x")
    submit(raw, 1, 2, IN, 64)
    assert raw.reply(in_direction=True) == RetSubmit(1, 0, 1, b"x")
    raw.sock.sendall(CmdUnlink(2, DEVID, 1).encode())
    assert raw.reply() == RetUnlink(2, 0)


def test_zero_length_in_urb_completes_at_once(raw: RawHost) -> None:
    raw.import_device()
    submit(raw, 1, 2, IN, 0)
    assert raw.reply() == RetSubmit(1, 0, 0)


def test_second_import_gets_dev_busy(server: UsbipCdcServer, raw: RawHost) -> None:
    assert raw.import_device().status == OpStatus.OK
    assert server.wait_attached(5.0)
    other = RawHost(server.port)
    try:
        assert other.import_device().status == OpStatus.DEV_BUSY
    finally:
        other.close()
    submit(raw, 1, 2, OUT, data=b"ok")
    assert raw.reply() == RetSubmit(1, 0, 2)
