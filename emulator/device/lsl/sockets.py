"""What a process listens on, read from Linux's /proc: its TCP sockets in LISTEN and its unconnected UDP sockets.

`parse_table` reads one of /proc/net/{tcp,tcp6,udp,udp6} (pure); `listening(pid)` joins those tables with the
process's open socket descriptors (/proc/<pid>/fd). Used by the LSL outlet process to say what it binds, and by
the tests to check it. Addresses are printed as the kernel stores them (IPv4 dotted, IPv6 compressed).
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass

TABLES = ("tcp", "tcp6", "udp", "udp6")
TCP_LISTEN, UDP_UNCONNECTED = "0A", "07"  # the kernel's socket states (include/net/tcp_states.h)


@dataclass(frozen=True)
class Bound:
    """One listening socket: "tcp" or "udp", its local address and port."""

    protocol: str
    address: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.address}]" if ":" in self.address else self.address
        return f"{self.protocol} {host}:{self.port}"

    @property
    def loopback(self) -> bool:
        """Reachable from this machine only."""
        return ipaddress.ip_address(self.address).is_loopback


def _address(hex_address: str) -> str:
    """The kernel's hex form (each 32-bit word in host byte order, little-endian here) as an address."""
    raw = bytes.fromhex(hex_address)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    return str(ipaddress.ip_address(words))


def parse_table(text: str, table: str, inodes: set[str]) -> list[Bound]:
    """The listening sockets of `inodes` in the text of /proc/net/`table`."""
    protocol, wanted = table.rstrip("6"), TCP_LISTEN if table.startswith("tcp") else UDP_UNCONNECTED
    out = []
    for line in text.splitlines()[1:]:
        fields = line.split()
        if len(fields) < 10 or fields[9] not in inodes or fields[3] != wanted:
            continue
        address, _, port = fields[1].partition(":")
        out.append(Bound(protocol, _address(address), int(port, 16)))
    return out


def socket_inodes(pid: int | str = "self") -> set[str]:
    """The inodes of the sockets open in process `pid`."""
    out = set()
    base = f"/proc/{pid}/fd"
    for fd in os.listdir(base):
        try:
            target = os.readlink(f"{base}/{fd}")
        except OSError:  # closed meanwhile
            continue
        if target.startswith("socket:["):
            out.add(target[8:-1])
    return out


def listening(pid: int | str = "self") -> list[Bound]:
    """Every socket process `pid` listens on (Linux; OSError elsewhere or for a process we may not read)."""
    inodes = socket_inodes(pid)
    out: list[Bound] = []
    for table in TABLES:
        try:
            with open(f"/proc/{pid}/net/{table}") as f:
                out += parse_table(f.read(), table, inodes)
        except FileNotFoundError:  # no IPv6 in this kernel
            continue
    return sorted(set(out), key=lambda b: (b.protocol, b.port, b.address))
