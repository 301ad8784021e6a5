"""The virtual tracker as a USB CDC-ACM (virtual serial) device, exported over USB/IP.

- `link`: `UsbipLink`, the device link a `LinkRunner` drives;
- `server`: the USB/IP server (device list, import, one connection per attached host);
- `session`: the URB phase of one attached host (bulk IN/OUT, interrupt, unlink);
- `control`: endpoint 0 (standard and CDC-ACM class requests).
"""
