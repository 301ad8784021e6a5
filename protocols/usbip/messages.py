"""USB/IP wire messages (protocol version 0x0111, TCP port 3240): a pure codec, no I/O.

USB/IP carries USB request blocks (URBs) over TCP. Every integer is **big-endian** (network order),
strings are NUL-padded ASCII; the 8-byte USB setup packet inside CMD_SUBMIT keeps USB's own
little-endian layout (see `eyehil.protocols.usbip.descriptors.SetupPacket`). A connection starts with one
operation (op) request; after a successful import it carries URB messages until it closes.

Op header (8 bytes), then the op's body::

    0  u16 version (0x0111)   2  u16 code   4  u32 status (0 in requests; OpStatus in replies)

    OP_REQ_DEVLIST 0x8005  header only
    OP_REP_DEVLIST 0x0005  header, u32 n_devices, then per device: usb_device (312 bytes)
                           followed by bNumInterfaces usb_interface records (4 bytes each)
    OP_REQ_IMPORT  0x8003  header, busid (32 bytes, NUL-padded)
    OP_REP_IMPORT  0x0003  header; if status == 0, one usb_device (312 bytes, no interfaces)

usb_device (312 bytes)::

    0 path[256]  256 busid[32]  288 u32 busnum  292 u32 devnum  296 u32 speed (Linux usb_device_speed)
    300 u16 idVendor  302 u16 idProduct  304 u16 bcdDevice  306 u8 bDeviceClass  307 u8 bDeviceSubClass
    308 u8 bDeviceProtocol  309 u8 bConfigurationValue  310 u8 bNumConfigurations  311 u8 bNumInterfaces

usb_interface (4 bytes): u8 bInterfaceClass, u8 bInterfaceSubClass, u8 bInterfaceProtocol, u8 padding.

URB messages (after a successful import) are in `eyehil.protocols.usbip.urb`. `cdc_acm_device` is the record of the
eyehil device (VID:PID 1209:0001, high-speed, busid 1-1, devid 0x00010002).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from enum import IntEnum

from eyehil.protocols.usbip.descriptors import (
    BCD_DEVICE,
    CLASS_CDC,
    CLASS_CDC_DATA,
    PRODUCT_ID,
    SUBCLASS_ACM,
    VENDOR_ID,
)

USBIP_VERSION = 0x0111
USBIP_PORT = 3240

OP_HEADER = struct.Struct(">HHI")
USB_DEVICE = struct.Struct(">256s32sIIIHHHBBBBBB")
USB_INTERFACE = struct.Struct(">BBBx")
BUSID_SIZE = 32


class UsbipError(ValueError):
    """The bytes are not a well-formed USB/IP message."""


class OpCode(IntEnum):
    REQ_DEVLIST = 0x8005
    REP_DEVLIST = 0x0005
    REQ_IMPORT = 0x8003
    REP_IMPORT = 0x0003


class OpStatus(IntEnum):
    OK = 0
    NA = 1
    DEV_BUSY = 2
    DEV_ERR = 3
    NODEV = 4
    ERROR = 5


class Speed(IntEnum):
    """Linux `enum usb_device_speed`, as carried in usb_device.speed."""

    UNKNOWN = 0
    LOW = 1
    FULL = 2
    HIGH = 3
    WIRELESS = 4
    SUPER = 5
    SUPER_PLUS = 6


def _check_size(data: bytes, size: int, what: str) -> None:
    if len(data) != size:
        raise UsbipError(f"{what}: expected {size} bytes, got {len(data)}")


def _cstring(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="replace")


def _pad(text: str, size: int) -> bytes:
    raw = text.encode("ascii")
    if len(raw) >= size:
        raise ValueError(f"{text!r} does not fit {size - 1} ASCII bytes")
    return raw.ljust(size, b"\0")


@dataclass(frozen=True)
class OpHeader:
    """The 8-byte header of every op request and reply."""

    code: int
    status: int = OpStatus.OK
    version: int = USBIP_VERSION

    def encode(self) -> bytes:
        return OP_HEADER.pack(self.version, self.code, self.status)

    @classmethod
    def decode(cls, data: bytes) -> OpHeader:
        _check_size(data, OP_HEADER.size, "op header")
        version, code, status = OP_HEADER.unpack(data)
        return cls(code=code, status=status, version=version)


@dataclass(frozen=True)
class UsbInterface:
    """One usb_interface record of a devlist reply."""

    interface_class: int
    interface_subclass: int
    interface_protocol: int

    def encode(self) -> bytes:
        return USB_INTERFACE.pack(self.interface_class, self.interface_subclass, self.interface_protocol)

    @classmethod
    def decode(cls, data: bytes) -> UsbInterface:
        _check_size(data, USB_INTERFACE.size, "usb_interface")
        return cls(*USB_INTERFACE.unpack(data))


@dataclass(frozen=True)
class UsbDevice:
    """The usb_device record: what a devlist lists and an import reply confirms."""

    path: str
    busid: str
    busnum: int
    devnum: int
    speed: int
    id_vendor: int
    id_product: int
    bcd_device: int
    device_class: int
    device_subclass: int
    device_protocol: int
    configuration_value: int
    num_configurations: int
    interfaces: tuple[UsbInterface, ...] = ()

    @property
    def devid(self) -> int:
        """The devid carried by every URB of an imported device."""
        return (self.busnum << 16) | self.devnum

    def encode(self) -> bytes:
        """The 312-byte record alone (as in OP_REP_IMPORT); bNumInterfaces counts `interfaces`."""
        return USB_DEVICE.pack(
            _pad(self.path, 256), _pad(self.busid, BUSID_SIZE), self.busnum, self.devnum, self.speed,
            self.id_vendor, self.id_product, self.bcd_device, self.device_class, self.device_subclass,
            self.device_protocol, self.configuration_value, self.num_configurations, len(self.interfaces))

    def encode_with_interfaces(self) -> bytes:
        """The record followed by its interface records (as in OP_REP_DEVLIST)."""
        return self.encode() + b"".join(i.encode() for i in self.interfaces)

    @classmethod
    def decode(cls, data: bytes) -> tuple[UsbDevice, int]:
        """Decode a 312-byte record; returns the device (no interfaces yet) and bNumInterfaces."""
        _check_size(data, USB_DEVICE.size, "usb_device")
        path, busid, *numbers, num_interfaces = USB_DEVICE.unpack(data)
        return cls(_cstring(path), _cstring(busid), *numbers), num_interfaces


def encode_devlist_reply(devices: list[UsbDevice]) -> bytes:
    """OP_REP_DEVLIST: header, device count, each device with its interfaces."""
    body = b"".join(d.encode_with_interfaces() for d in devices)
    return OpHeader(OpCode.REP_DEVLIST).encode() + struct.pack(">I", len(devices)) + body


def decode_devlist_reply(data: bytes) -> list[UsbDevice]:
    """Decode a complete OP_REP_DEVLIST (as `encode_devlist_reply` makes it)."""
    header = OpHeader.decode(data[: OP_HEADER.size])
    if header.code != OpCode.REP_DEVLIST or header.status != OpStatus.OK:
        raise UsbipError(f"not a successful devlist reply: {header}")
    (count,), pos, devices = struct.unpack_from(">I", data, OP_HEADER.size), OP_HEADER.size + 4, []
    for _ in range(count):
        device, n_interfaces = UsbDevice.decode(data[pos: pos + USB_DEVICE.size])
        pos += USB_DEVICE.size
        raw = [data[pos + USB_INTERFACE.size * i: pos + USB_INTERFACE.size * (i + 1)] for i in range(n_interfaces)]
        pos += USB_INTERFACE.size * n_interfaces
        devices.append(replace(device, interfaces=tuple(UsbInterface.decode(r) for r in raw)))
    _check_size(data, pos, "devlist reply")
    return devices


def encode_import_request(busid: str) -> bytes:
    return OpHeader(OpCode.REQ_IMPORT).encode() + _pad(busid, BUSID_SIZE)


def decode_busid(data: bytes) -> str:
    """The busid of an OP_REQ_IMPORT body (32 bytes after the header)."""
    _check_size(data, BUSID_SIZE, "busid")
    return _cstring(data)


def encode_import_reply(device: UsbDevice | None, status: int = OpStatus.OK) -> bytes:
    """OP_REP_IMPORT: the device record follows only on success."""
    header = OpHeader(OpCode.REP_IMPORT, status).encode()
    return header + device.encode() if status == OpStatus.OK and device is not None else header


def cdc_acm_device(busid: str = "1-1", busnum: int = 1, devnum: int = 2) -> UsbDevice:
    """The usb_device record the server lists and imports (high-speed, one configuration, two interfaces)."""
    return UsbDevice(path=f"/sys/devices/platform/eyehil/usb{busnum}/{busid}", busid=busid, busnum=busnum,
                     devnum=devnum, speed=Speed.HIGH, id_vendor=VENDOR_ID, id_product=PRODUCT_ID,
                     bcd_device=BCD_DEVICE, device_class=CLASS_CDC, device_subclass=0, device_protocol=0,
                     configuration_value=0, num_configurations=1,
                     interfaces=(UsbInterface(CLASS_CDC, SUBCLASS_ACM, 0), UsbInterface(CLASS_CDC_DATA, 0, 0)))
