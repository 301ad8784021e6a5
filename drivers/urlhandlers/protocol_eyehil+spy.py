"""pyserial URL handler for ``eyehil+spy://``: see `eyehil.drivers.urlhandlers`."""

from eyehil.drivers.urlhandlers.serial_port import EyehilSerial as Serial

__all__ = ["Serial"]
