"""pyserial URL handler for ``eyehil+usbip://``: see `eyehil.drivers.urlhandlers`."""

from eyehil.drivers.urlhandlers.serial_port import EyehilSerial as Serial

__all__ = ["Serial"]
