"""USB/IP and the virtual CDC-ACM device it carries: pure codecs, no I/O.

- `messages`: USB/IP operation messages (device list, import; protocol 0x0111, TCP port 3240);
- `urb`: URB messages (CMD_SUBMIT, RET_SUBMIT, CMD_UNLINK, RET_UNLINK);
- `descriptors`: the device's USB descriptors (CDC-ACM: a virtual serial port).
"""
