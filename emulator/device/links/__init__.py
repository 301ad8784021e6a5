"""The device side of the links a host opens: each transport in a small module of its own.

- `base`: the `DeviceLink` and `DeviceCore` interfaces and `LinkRunner`, which joins a device core to a link;
- `fdlink`: the I/O thread shared by the file-descriptor links;
- `pty`: a pseudo-terminal (the host opens it like /dev/ttyACM0); `tcp`: a TCP server (pyserial ``socket://``);
- `loop`: an in-process, serial-like port whose other end is a device (``loop://``, for tests);
- `paced`: any link paced to a real link's byte rate on the device clock (``--link-rate``, ``link_rate=``);
- `listen`: `create_server` for the device's servers (tcp, usbip, opengaze), one clear `ListenError` if it
  cannot bind;
- `usbip/`: the virtual tracker as a USB CDC-ACM device exported over USB/IP.
"""
