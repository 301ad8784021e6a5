"""pyserial URL handler for ``eyehil+loop://``: see `eyehil.drivers.urlhandlers`."""

from eyehil.drivers.urlhandlers.serial_port import EyehilSerial as Serial

__all__ = ["Serial"]
