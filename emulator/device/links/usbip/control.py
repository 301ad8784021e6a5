"""Endpoint 0 of the virtual CDC-ACM device: the standard and CDC-ACM class control requests.

Pure state, no I/O: `CdcAcmControl.handle(setup, data)` returns the data stage of the reply (empty for
OUT requests) or None, which the USB/IP server turns into a stall (-EPIPE), as a real device answers a
request it does not support. Requests served (bmRequestType, bRequest):

    0x80 GET_DESCRIPTOR        device, configuration, string, device qualifier, other-speed config
    0x80 GET_CONFIGURATION     0x00 SET_CONFIGURATION (0 or 1)
    0x80/0x81/0x82 GET_STATUS  device (bus-powered), interface, endpoint (never halted)
    0x81 GET_INTERFACE         0x01 SET_INTERFACE (alternate setting 0 only)
    0x00/0x02 CLEAR_FEATURE, SET_FEATURE, 0x00 SET_ADDRESS   accepted, no effect
    0x21 SET_LINE_CODING 0x20  0xA1 GET_LINE_CODING 0x21  0x21 SET_CONTROL_LINE_STATE 0x22
    0x21 SEND_BREAK 0x23

Only the session thread of the attached host calls `handle`; other threads may read the state.
"""

from __future__ import annotations

from collections.abc import Callable

from eyehil.protocols.usbip.descriptors import (
    CLASS_IN_INTERFACE,
    CLASS_OUT_INTERFACE,
    COMM_INTERFACE,
    CONFIGURATION_VALUE,
    DATA_INTERFACE,
    EP_DATA_IN,
    EP_DATA_OUT,
    EP_NOTIFY,
    LINE_STATE_DTR,
    LINE_STATE_RTS,
    CdcAcmDescriptors,
    LineCoding,
    Request,
    SetupPacket,
)

Handler = Callable[[SetupPacket, bytes], bytes | None]
_INTERFACES = (COMM_INTERFACE, DATA_INTERFACE)
_ENDPOINTS = (0x00, 0x80, EP_NOTIFY, EP_DATA_OUT, EP_DATA_IN)


class CdcAcmControl:
    """The state behind endpoint 0: configuration, line coding and the host's DTR/RTS lines."""

    def __init__(self, descriptors: CdcAcmDescriptors | None = None) -> None:
        self.descriptors = descriptors or CdcAcmDescriptors()
        self._handlers: dict[tuple[int, int], Handler] = {
            (0x80, Request.GET_DESCRIPTOR): self._get_descriptor,
            (0x80, Request.GET_CONFIGURATION): lambda s, d: bytes([self.configuration]),
            (0x00, Request.SET_CONFIGURATION): self._set_configuration,
            (0x80, Request.GET_STATUS): lambda s, d: bytes(2),
            (0x81, Request.GET_STATUS): lambda s, d: bytes(2) if s.index in _INTERFACES else None,
            (0x82, Request.GET_STATUS): lambda s, d: bytes(2) if s.index in _ENDPOINTS else None,
            (0x81, Request.GET_INTERFACE): lambda s, d: bytes(1) if s.index in _INTERFACES else None,
            (0x01, Request.SET_INTERFACE): lambda s, d: b"" if s.index in _INTERFACES and s.value == 0 else None,
            (0x00, Request.CLEAR_FEATURE): _accept, (0x02, Request.CLEAR_FEATURE): _accept,
            (0x00, Request.SET_FEATURE): _accept, (0x02, Request.SET_FEATURE): _accept,
            (0x00, Request.SET_ADDRESS): _accept,
            (CLASS_OUT_INTERFACE, Request.SET_LINE_CODING): self._set_line_coding,
            (CLASS_IN_INTERFACE, Request.GET_LINE_CODING): lambda s, d: self.line_coding.encode(),
            (CLASS_OUT_INTERFACE, Request.SET_CONTROL_LINE_STATE): self._set_line_state,
            (CLASS_OUT_INTERFACE, Request.SEND_BREAK): _accept,
        }
        self.reset()

    def reset(self) -> None:
        """Back to the state after a bus reset: unconfigured, 115200 8N1, DTR and RTS low."""
        self.configuration = 0
        self.line_coding = LineCoding()
        self.line_state = 0

    @property
    def dtr(self) -> bool:
        """Data Terminal Ready as last set by the host (a terminal program sets it when it opens the port)."""
        return bool(self.line_state & LINE_STATE_DTR)

    @property
    def rts(self) -> bool:
        return bool(self.line_state & LINE_STATE_RTS)

    def handle(self, setup: SetupPacket, data: bytes) -> bytes | None:
        """The reply's data stage (truncated to wLength for IN requests), or None to stall."""
        handler = self._handlers.get((setup.request_type, setup.request))
        reply = handler(setup, data) if handler else None
        if reply is None:
            return None
        return reply[: setup.length] if setup.is_in else b""

    def _get_descriptor(self, setup: SetupPacket, data: bytes) -> bytes | None:
        return self.descriptors.lookup(setup.value >> 8, setup.value & 0xFF)

    def _set_configuration(self, setup: SetupPacket, data: bytes) -> bytes | None:
        if setup.value not in (0, CONFIGURATION_VALUE):
            return None
        self.configuration = setup.value
        return b""

    def _set_line_coding(self, setup: SetupPacket, data: bytes) -> bytes | None:
        if setup.index != COMM_INTERFACE:
            return None
        try:
            self.line_coding = LineCoding.decode(data)
        except ValueError:
            return None
        return b""

    def _set_line_state(self, setup: SetupPacket, data: bytes) -> bytes | None:
        if setup.index != COMM_INTERFACE:
            return None
        self.line_state = setup.value & (LINE_STATE_DTR | LINE_STATE_RTS)
        return b""


def _accept(setup: SetupPacket, data: bytes) -> bytes:
    return b""
