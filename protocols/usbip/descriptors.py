"""The USB identity of the virtual eye tracker: a CDC-ACM (virtual serial port) device. Pure, no I/O.

USB fields are little-endian (USB 2.0 chapter 9; CDC 1.2 and PSTN 1.2 for the class parts).

Identity: VID 0x1209 (pid.codes), PID 0x0001 (one of pid.codes' *test* PIDs 0x0001-0x0010, for private
testing only: a released product needs its own PID from pid.codes), bcdDevice 1.00, bcdUSB 2.00;
strings "eyehil", "eyehil virtual eye tracker" and a serial number.

Speed: **high-speed** (bulk wMaxPacketSize 512). The tracker streams camera frames: full-speed CDC
carries about 1 MB/s, three 640x480 frames per second, high-speed about 40 MB/s. It also matters on
a Linux host attached through vhci-hcd: cdc-acm sizes each read URB to wMaxPacketSize, so 512-byte
packets need 8x fewer URB round trips than 64-byte ones. As USB 2.0 (9.6.2) requires of a high-speed
device, it answers DEVICE_QUALIFIER and OTHER_SPEED_CONFIGURATION (its full-speed form: 64-byte bulk
packets).

Configuration 1 (67 bytes, bus-powered, 100 mA)::

    interface 0  class 0x02 CDC, subclass 0x02 ACM, protocol 0x00 (no AT commands)
                 header (CDC 1.10), call management (none, data interface 1),
                 ACM (bmCapabilities 0x02: line coding, line state, SERIAL_STATE), union (0 -> 1)
                 endpoint 0x81 interrupt IN, 16 bytes, every 16 ms (notifications)
    interface 1  class 0x0A CDC data
                 endpoint 0x02 bulk OUT (host -> device), endpoint 0x82 bulk IN (device -> host)
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

VENDOR_ID = 0x1209
PRODUCT_ID = 0x0001
BCD_DEVICE = 0x0100
MANUFACTURER = "eyehil"
PRODUCT = "eyehil virtual eye tracker"
LANGID_EN_US = 0x0409
EP_NOTIFY, EP_DATA_OUT, EP_DATA_IN = 0x81, 0x02, 0x82
COMM_INTERFACE, DATA_INTERFACE = 0, 1
CLASS_CDC, CLASS_CDC_DATA, SUBCLASS_ACM = 0x02, 0x0A, 0x02
CONFIGURATION_VALUE = 1
HIGH_SPEED_PACKET, FULL_SPEED_PACKET = 512, 64


class DescriptorType(IntEnum):
    DEVICE = 1
    CONFIGURATION = 2
    STRING = 3
    INTERFACE = 4
    ENDPOINT = 5
    DEVICE_QUALIFIER = 6
    OTHER_SPEED_CONFIGURATION = 7
    CS_INTERFACE = 0x24


class Request(IntEnum):
    """Standard requests (bRequest) and the CDC-ACM class requests of the communications interface."""

    GET_STATUS = 0x00
    CLEAR_FEATURE = 0x01
    SET_FEATURE = 0x03
    SET_ADDRESS = 0x05
    GET_DESCRIPTOR = 0x06
    GET_CONFIGURATION = 0x08
    SET_CONFIGURATION = 0x09
    GET_INTERFACE = 0x0A
    SET_INTERFACE = 0x0B
    SET_LINE_CODING = 0x20  # bmRequestType 0x21, 7 bytes OUT
    GET_LINE_CODING = 0x21  # bmRequestType 0xA1, 7 bytes IN
    SET_CONTROL_LINE_STATE = 0x22  # bmRequestType 0x21, wValue bit 0 DTR, bit 1 RTS
    SEND_BREAK = 0x23  # bmRequestType 0x21, wValue duration in ms


CLASS_OUT_INTERFACE, CLASS_IN_INTERFACE = 0x21, 0xA1
LINE_STATE_DTR, LINE_STATE_RTS = 0x01, 0x02
_SETUP = struct.Struct("<BBHHH")
_LINE_CODING = struct.Struct("<IBBB")


@dataclass(frozen=True)
class SetupPacket:
    """The 8-byte setup packet of a control transfer."""

    request_type: int
    request: int
    value: int = 0
    index: int = 0
    length: int = 0

    @property
    def is_in(self) -> bool:
        """Data stage device -> host (bmRequestType bit 7)."""
        return bool(self.request_type & 0x80)

    def encode(self) -> bytes:
        return _SETUP.pack(self.request_type, self.request, self.value, self.index, self.length)

    @classmethod
    def decode(cls, data: bytes) -> SetupPacket:
        if len(data) != _SETUP.size:
            raise ValueError(f"setup packet: expected 8 bytes, got {len(data)}")
        return cls(*_SETUP.unpack(data))


@dataclass(frozen=True)
class LineCoding:
    """CDC line coding (PSTN 1.2, 6.3.11): stop bits 0/1/2 = 1/1.5/2, parity 0..4 = none/odd/even/mark/space."""

    baudrate: int = 115200
    stop_bits: int = 0
    parity: int = 0
    data_bits: int = 8

    def encode(self) -> bytes:
        return _LINE_CODING.pack(self.baudrate, self.stop_bits, self.parity, self.data_bits)

    @classmethod
    def decode(cls, data: bytes) -> LineCoding:
        if len(data) != _LINE_CODING.size:
            raise ValueError(f"line coding: expected 7 bytes, got {len(data)}")
        return cls(*_LINE_CODING.unpack(data))


def string_descriptor(text: str) -> bytes:
    """A string descriptor: UTF-16LE, at most 126 characters."""
    raw = text.encode("utf-16-le")
    if len(raw) > 252:
        raise ValueError("string descriptor longer than 126 UTF-16 units")
    return bytes([2 + len(raw), DescriptorType.STRING]) + raw


def _endpoint(address: int, attributes: int, max_packet: int, interval: int) -> bytes:
    return struct.pack("<BBBBHB", 7, DescriptorType.ENDPOINT, address, attributes, max_packet, interval)


def _interface(number: int, endpoints: int, cls: int, subclass: int) -> bytes:
    return struct.pack("<9B", 9, DescriptorType.INTERFACE, number, 0, endpoints, cls, subclass, 0, 0)


def _cdc_functional() -> bytes:
    header = struct.pack("<BBBH", 5, DescriptorType.CS_INTERFACE, 0x00, 0x0110)
    call_management = bytes([5, DescriptorType.CS_INTERFACE, 0x01, 0x00, DATA_INTERFACE])
    acm = bytes([4, DescriptorType.CS_INTERFACE, 0x02, 0x02])
    union = bytes([5, DescriptorType.CS_INTERFACE, 0x06, COMM_INTERFACE, DATA_INTERFACE])
    return header + call_management + acm + union


def configuration_descriptor(high_speed: bool = True, other_speed: bool = False) -> bytes:
    """Configuration 1 with its interfaces and endpoints (67 bytes); `other_speed` gives type 7."""
    packet, interval = (HIGH_SPEED_PACKET, 8) if high_speed else (FULL_SPEED_PACKET, 16)  # both 16 ms
    body = (_interface(COMM_INTERFACE, 1, CLASS_CDC, SUBCLASS_ACM) + _cdc_functional()
            + _endpoint(EP_NOTIFY, 0x03, 16, interval)
            + _interface(DATA_INTERFACE, 2, CLASS_CDC_DATA, 0)
            + _endpoint(EP_DATA_OUT, 0x02, packet, 0) + _endpoint(EP_DATA_IN, 0x02, packet, 0))
    kind = DescriptorType.OTHER_SPEED_CONFIGURATION if other_speed else DescriptorType.CONFIGURATION
    head = struct.pack("<BBHBBBBB", 9, kind, 9 + len(body), 2, CONFIGURATION_VALUE, 0, 0x80, 50)
    return head + body


def device_descriptor() -> bytes:
    """The 18-byte device descriptor (class 0x02 at device level, EP0 64 bytes, one configuration)."""
    return struct.pack("<BBHBBBBHHHBBBB", 18, DescriptorType.DEVICE, 0x0200, CLASS_CDC, 0, 0, 64,
                       VENDOR_ID, PRODUCT_ID, BCD_DEVICE, 1, 2, 3, 1)


def device_qualifier_descriptor() -> bytes:
    """The 10-byte device qualifier: what the device would be at the other (full) speed."""
    return struct.pack("<BBHBBBBBB", 10, DescriptorType.DEVICE_QUALIFIER, 0x0200, CLASS_CDC, 0, 0, 64, 1, 0)


@dataclass(frozen=True)
class CdcAcmDescriptors:
    """Every descriptor the device answers GET_DESCRIPTOR with; only the serial number varies."""

    serial: str = "EYEHIL-0001"

    def strings(self) -> tuple[str, ...]:
        return (MANUFACTURER, PRODUCT, self.serial)

    def lookup(self, kind: int, index: int) -> bytes | None:
        """The descriptor for GET_DESCRIPTOR (wValue = kind << 8 | index), or None (the request stalls)."""
        if kind == DescriptorType.STRING:
            return self._string(index)
        if index != 0:
            return None
        table = {DescriptorType.DEVICE: device_descriptor,
                 DescriptorType.CONFIGURATION: configuration_descriptor,
                 DescriptorType.DEVICE_QUALIFIER: device_qualifier_descriptor,
                 DescriptorType.OTHER_SPEED_CONFIGURATION: lambda: configuration_descriptor(False, True)}
        build = table.get(kind)
        return build() if build else None

    def _string(self, index: int) -> bytes | None:
        if index == 0:
            return struct.pack("<BBH", 4, DescriptorType.STRING, LANGID_EN_US)
        texts = self.strings()
        return string_descriptor(texts[index - 1]) if index <= len(texts) else None


@dataclass(frozen=True)
class CdcEndpoints:
    """What a host needs from a CDC-ACM configuration: interface numbers and endpoint addresses."""

    comm_interface: int
    data_interface: int
    bulk_in: int
    bulk_out: int
    max_packet: int
    notify: int | None = None


def iter_descriptors(blob: bytes) -> list[bytes]:
    """Split a configuration descriptor (with everything after it) into its descriptors."""
    parts, pos = [], 0
    while pos < len(blob):
        length = blob[pos]
        if length < 2 or pos + length > len(blob):
            raise ValueError(f"truncated or invalid descriptor at offset {pos}")
        parts.append(blob[pos: pos + length])
        pos += length
    return parts


def find_cdc_endpoints(config: bytes) -> CdcEndpoints:
    """Locate the communications and data interfaces and their endpoints; ValueError if not CDC-ACM."""
    found: dict[str, int] = {}
    klass = None
    for d in iter_descriptors(config):
        if d[1] == DescriptorType.INTERFACE and len(d) >= 9:
            klass = d[5]
            found.setdefault("comm" if klass == CLASS_CDC else "data" if klass == CLASS_CDC_DATA else "other", d[2])
        elif d[1] == DescriptorType.ENDPOINT and len(d) >= 7:
            address, kind, packet = d[2], d[3] & 0x03, struct.unpack_from("<H", d, 4)[0] & 0x7FF
            if klass == CLASS_CDC and kind == 0x03:
                found.setdefault("notify", address)
            elif klass == CLASS_CDC_DATA and kind == 0x02:
                found.setdefault("bulk_in" if address & 0x80 else "bulk_out", address)
                found["max_packet"] = packet
    missing = {"comm", "data", "bulk_in", "bulk_out"} - found.keys()
    if missing:
        raise ValueError(f"not a CDC-ACM configuration: no {', '.join(sorted(missing))}")
    return CdcEndpoints(found["comm"], found["data"], found["bulk_in"], found["bulk_out"], found["max_packet"],
                        found.get("notify"))
