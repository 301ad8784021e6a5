"""USB descriptors of the CDC-ACM device (known answers) and the endpoint-0 request handler."""

from __future__ import annotations

import pytest

from eyehil.emulator.device.links.usbip.control import CdcAcmControl
from eyehil.protocols.usbip.descriptors import (
    CdcAcmDescriptors,
    CdcEndpoints,
    DescriptorType,
    LineCoding,
    Request,
    SetupPacket,
    configuration_descriptor,
    device_descriptor,
    find_cdc_endpoints,
    iter_descriptors,
    string_descriptor,
)


def test_device_descriptor_known_answer() -> None:
    # bLength 18, DEVICE, bcdUSB 2.00, class 02/00/00, EP0 64, VID 1209, PID 0001, bcdDevice 1.00,
    # strings 1/2/3, one configuration
    assert device_descriptor() == bytes.fromhex("1201 0002 020000 40 0912 0100 0001 010203 01")


def test_configuration_descriptor_layout() -> None:
    config = configuration_descriptor()
    assert len(config) == 67 and config[:9] == bytes.fromhex("09 02 4300 02 01 00 80 32")
    parts = iter_descriptors(config)
    assert [p[1] for p in parts] == [2, 4, 0x24, 0x24, 0x24, 0x24, 5, 4, 5, 5]
    assert parts[2] == bytes.fromhex("0524001001")  # CDC header, bcdCDC 1.10
    assert parts[4] == bytes.fromhex("04240202")  # ACM: line coding and line state requests
    assert parts[5] == bytes.fromhex("0524060001")  # union: master 0, slave 1
    assert parts[6] == bytes.fromhex("07058103100008")  # interrupt IN 0x81, 16 bytes, 2^(8-1) microframes
    assert parts[8:] == [bytes.fromhex("07050202000200"), bytes.fromhex("07058202000200")]  # bulk, 512 bytes


def test_full_speed_other_speed_configuration() -> None:
    other = CdcAcmDescriptors().lookup(DescriptorType.OTHER_SPEED_CONFIGURATION, 0)
    assert other is not None and other[1] == DescriptorType.OTHER_SPEED_CONFIGURATION
    assert find_cdc_endpoints(other).max_packet == 64
    qualifier = CdcAcmDescriptors().lookup(DescriptorType.DEVICE_QUALIFIER, 0)
    assert qualifier == bytes.fromhex("0a06 0002 020000 40 01 00")


def test_find_cdc_endpoints() -> None:
    assert find_cdc_endpoints(configuration_descriptor()) == CdcEndpoints(0, 1, 0x82, 0x02, 512, 0x81)
    with pytest.raises(ValueError, match="not a CDC-ACM"):
        find_cdc_endpoints(configuration_descriptor()[:18])
    with pytest.raises(ValueError, match="invalid descriptor"):
        iter_descriptors(bytes([9, 2, 0]))


def test_string_descriptors() -> None:
    strings = CdcAcmDescriptors("SN42")
    assert strings.lookup(DescriptorType.STRING, 0) == bytes.fromhex("04030904")  # English (US)
    assert strings.lookup(DescriptorType.STRING, 1) == bytes.fromhex("0e03") + "eyehil".encode("utf-16-le")
    assert strings.lookup(DescriptorType.STRING, 2) == string_descriptor("eyehil virtual eye tracker")
    assert strings.lookup(DescriptorType.STRING, 3) == bytes.fromhex("0a03 5300 4e00 3400 3200")
    assert strings.lookup(DescriptorType.STRING, 4) is None
    assert strings.lookup(DescriptorType.DEVICE, 1) is None and strings.lookup(0x0F, 0) is None


def test_setup_packet_and_line_coding_known_answers() -> None:
    setup = SetupPacket(0x80, Request.GET_DESCRIPTOR, 0x0100, 0, 18)
    assert setup.encode() == bytes.fromhex("8006000100001200") and setup.is_in
    assert SetupPacket.decode(setup.encode()) == setup
    assert LineCoding(115200).encode() == bytes.fromhex("00c20100 00 00 08")
    assert LineCoding.decode(bytes.fromhex("00100e00 02 01 07")) == LineCoding(921600, 2, 1, 7)
    with pytest.raises(ValueError):
        LineCoding.decode(bytes(6))


def test_control_descriptors_are_truncated_to_wlength() -> None:
    control = CdcAcmControl()
    assert control.handle(SetupPacket(0x80, 6, 0x0100, 0, 64), b"") == device_descriptor()
    assert control.handle(SetupPacket(0x80, 6, 0x0100, 0, 8), b"") == device_descriptor()[:8]
    assert control.handle(SetupPacket(0x80, 6, 0x0200, 0, 9), b"") == configuration_descriptor()[:9]


def test_control_configuration_and_cdc_requests() -> None:
    control = CdcAcmControl()
    assert control.handle(SetupPacket(0x00, 9, 1), b"") == b"" and control.configuration == 1
    assert control.handle(SetupPacket(0x80, 8, 0, 0, 1), b"") == b"\x01"
    assert control.handle(SetupPacket(0x00, 9, 2), b"") is None  # no configuration 2: stall
    coding = LineCoding(9600, 0, 2, 7).encode()
    assert control.handle(SetupPacket(0x21, 0x20, 0, 0, 7), coding) == b""
    assert control.handle(SetupPacket(0xA1, 0x21, 0, 0, 7), b"") == coding
    assert control.handle(SetupPacket(0x21, 0x20, 0, 0, 6), coding[:6]) is None
    assert control.handle(SetupPacket(0x21, 0x22, 0x0001), b"") == b"" and control.dtr and not control.rts
    control.reset()
    assert control.configuration == 0 and not control.dtr and control.line_coding == LineCoding()


@pytest.mark.parametrize("setup", [
    SetupPacket(0xC0, 0x01, 0, 0, 4),  # vendor request
    SetupPacket(0x01, 0x0B, 1, 1),  # alternate setting 1 does not exist
    SetupPacket(0x81, 0x0A, 0, 5, 1),  # interface 5 does not exist
    SetupPacket(0x21, 0x22, 3, 1),  # line state addressed to the data interface
    SetupPacket(0x80, 0x06, 0x0304, 0x0409, 255),  # string 4 does not exist
])
def test_control_unsupported_requests_stall(setup: SetupPacket) -> None:
    assert CdcAcmControl().handle(setup, bytes(setup.length if not setup.is_in else 0)) is None
