"""Issue 11, finding 12: liblsl's stream discovery answers on the loopback only (what liblsl lets us bind)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("pylsl")

PROBE = textwrap.dedent("""
    import os, time
    from eyehil.emulator.device.lsl import load_pylsl
    pylsl = load_pylsl()
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo("probe", "Gaze", 1, 100, pylsl.cf_double64, "probe"))
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    for table in ("udp", "udp6"):
        for line in open(f"/proc/net/{table}").read().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes:
                print(table, fields[1])
""")


def test_lsl_discovery_binds_the_loopback_only() -> None:
    env = {k: v for k, v in os.environ.items() if k != "LSLAPICFG"}
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=120,
                         check=True).stdout.split("\n")
    discovery = [line for line in out if line.endswith(":40BB")]  # port 16571, liblsl's multicast port
    assert discovery and all(line == "udp 0100007F:40BB" for line in discovery), out
    assert not any(line.startswith("udp6") for line in out), out
