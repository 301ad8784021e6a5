"""eyehil's links as pyserial URL handlers, so that plain `serial.serial_for_url` code opens them.

pyserial maps a URL ``SCHEME://...`` to the module ``protocol_SCHEME`` of every package in
`serial.protocol_handler_packages`; `import eyehil` (and the eyehil pytest plugin) adds this package there.

- ``eyehil+loop://?scene=guestrin2006&clock=fast``: an in-process virtual tracker (`protocol_eyehil+loop`);
- ``eyehil+usbip://host:3240/1-1``: the virtual tracker's USB/IP export (`protocol_eyehil+usbip`);
- ``eyehil+spy://URL``: any eyehil URL with a hex dump of the traffic (`protocol_eyehil+spy`);
- `serial_port`: `EyehilSerial`, the `serial.SerialBase` they all return, over `eyehil.drivers.links.open_link`.

The options after ``?`` are those of the plain schemes (`eyehil.drivers.links`), which `open_tracker` keeps
accepting with or without the ``eyehil+`` prefix.
"""
