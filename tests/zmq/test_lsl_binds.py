"""Issue 11, finding 12: every socket of the LSL outlet listens on the loopback unless told otherwise.

liblsl binds its data and time ports to every interface and has no option against it; the outlet runs in a
process of its own with the loopback bind library preloaded (`lsl.loopback`). What a process listens on is read
from /proc (`lsl.sockets`). Also: the pipe to that process (`lsl.wire`) and its limits."""

from __future__ import annotations

import io
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eyehil.emulator.device.lsl import loopback, wire
from eyehil.emulator.device.lsl.library import LslUnavailableError, load_pylsl
from eyehil.emulator.device.lsl.outlet import MAX_PENDING, OutletProcess
from eyehil.emulator.device.lsl.sockets import Bound, listening, parse_table

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and LD_PRELOAD: Linux only")

try:
    pylsl = load_pylsl()
    NO_LSL = ""
except LslUnavailableError as exc:
    pylsl, NO_LSL = None, str(exc)
needs_lsl = pytest.mark.skipif(pylsl is None, reason=NO_LSL)

STREAM = {"name": "probe", "type": "Gaze", "rate_hz": 100.0, "source_id": "eyehil-test-probe",
          "manufacturer": "eyehil", "model": "test", "channels": [{"label": "a"}, {"label": "b"}]}


@needs_lsl
def test_every_socket_of_the_outlet_listens_on_the_loopback(server) -> None:
    srv = server(scene="guestrin2006", rate_hz=100, lsl=True)
    process = srv.outlet.process
    bound = listening(process.pid)
    assert {b.protocol for b in bound} == {"tcp", "udp"}, bound  # the data port; the discovery and time ports
    assert all(b.loopback for b in bound), bound
    assert process.ready["moved"] >= 2 and process.library_note == ""  # the library moved the data and time ports
    assert [str(b) for b in bound] == process.listening  # what it printed at start is what it binds
    assert process.ready["beyond_loopback"] == [] and "reachable" not in process.exposure()
    streams = pylsl.resolve_byprop("source_id", srv.outlet_source_id, timeout=10)
    inlet = pylsl.StreamInlet(streams[0])
    try:
        sample, _stamp = inlet.pull_sample(timeout=10)
        assert sample is not None  # data over the loopback data port
        assert abs(inlet.time_correction(timeout=10)) < 0.01  # and the time port answers (same machine, same clock)
    finally:
        inlet.close_stream()


@needs_lsl
def test_told_otherwise_the_outlet_listens_on_every_interface(server) -> None:
    srv = server(scene="guestrin2006", rate_hz=100, lsl=True, host="0.0.0.0")
    process = srv.outlet.process
    data = [b for b in listening(process.pid) if b.protocol == "tcp"]
    assert data and all(b.address in ("0.0.0.0", "::") for b in data), data
    assert process.ready["moved"] is None  # no library in that process


@needs_lsl
def test_without_a_compiler_the_outlet_runs_and_says_its_ports_are_open(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("EYEHIL_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    process = OutletProcess(STREAM)
    try:
        assert "no C compiler" in process.library_note and "reachable from other machines: tcp" in process.exposure()
        data = [b for b in listening(process.pid) if b.protocol == "tcp"]
        assert data and not any(b.loopback for b in data)
    finally:
        process.close()
    assert process.proc.returncode == 0


@needs_lsl
def test_a_stalled_outlet_process_never_blocks_the_sender() -> None:
    process = OutletProcess(STREAM)
    rows, stamps = np.zeros((1000, 2)), np.arange(1000.0)  # 16 kB a chunk: the pipe holds a few
    os.kill(process.pid, signal.SIGSTOP)
    try:
        taken = sum(process.send(rows, stamps) for _ in range(MAX_PENDING + 100))
        assert MAX_PENDING <= taken < MAX_PENDING + 20  # the queue, the writer's chunk, what the pipe holds
        assert process.dropped == (MAX_PENDING + 100 - taken) * 1000 and process.sent == taken * 1000
    finally:
        os.kill(process.pid, signal.SIGCONT)
        process.close()
    assert process.proc.returncode == 0  # it pushed what waited and ended at the end of its input
    ended = OutletProcess(STREAM)
    ended.proc.kill()
    ended.proc.wait()
    assert not ended.send(rows, stamps) and ended.dropped == 1000  # an ended process: counted, not raised
    ended.close()


def test_the_loopback_library_is_built_once_per_source(tmp_path, monkeypatch) -> None:
    if shutil.which(os.environ.get("CC") or "cc") is None:
        pytest.skip("no C compiler")
    first = loopback.library(tmp_path)
    assert first.parent == tmp_path and first.name.startswith("loopback_bind-") and first.suffix == ".so"
    made = first.stat().st_mtime_ns
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))  # a second build would fail: it is not needed
    assert loopback.library(tmp_path) == first and first.stat().st_mtime_ns == made
    assert sorted(p.name for p in tmp_path.iterdir()) == [first.name]  # no scratch file left
    with pytest.raises(loopback.LibraryUnavailableError, match="no C compiler"):
        loopback.library(tmp_path / "elsewhere")
    with pytest.raises(loopback.LibraryUnavailableError, match="a space or colon"):
        loopback.library(tmp_path / "my cache")
    env = loopback.preloaded({"LD_PRELOAD": "/x/other.so"}, first)
    assert env["LD_PRELOAD"] == f"{first} /x/other.so"


PROC_TCP = """  sl  local_address rem_address   st tx_queue rx_queue tr tm->when retrnsmt   uid  timeout inode
   0: 0100007F:40BC 00000000:0000 0A 00000000:00000000 00:00000000 00000000  1000        0 111 1 0 100 0 0 10 0
   1: 00000000:C350 00000000:0000 0A 00000000:00000000 00:00000000 00000000  1000        0 222 1 0 100 0 0 10 0
   2: 0100007F:9C40 0100007F:40BC 01 00000000:00000000 00:00000000 00000000  1000        0 333 1 0 100 0 0 10 0
   3: 0100007F:1F90 00000000:0000 0A 00000000:00000000 00:00000000 00000000  1000        0 444 1 0 100 0 0 10 0
"""
ZEROS = "00000000000000000000000000000000:0000"
PROC_TCP6 = f"""  sl  local_address                         remote_address                        st ...
   0: 00000000000000000000000001000000:40BD {ZEROS} 0A 00000000:00000000 00:00000000 00000000  1000  0 555 1
   1: 00000000000000000000000000000000:40BE {ZEROS} 0A 00000000:00000000 00:00000000 00000000  1000  0 666 1
"""


def test_proc_tables_are_read_as_addresses() -> None:
    inodes = {"111", "222", "333", "555", "666"}  # 444 is another process's; 333 is a connection
    assert parse_table(PROC_TCP, "tcp", inodes) == [Bound("tcp", "127.0.0.1", 16572), Bound("tcp", "0.0.0.0", 50000)]
    six = parse_table(PROC_TCP6, "tcp6", inodes)
    assert six == [Bound("tcp", "::1", 16573), Bound("tcp", "::", 16574)]
    assert [b.loopback for b in six] == [True, False] and str(six[0]) == "tcp [::1]:16573"
    assert parse_table(PROC_TCP.replace(" 0A ", " 07 "), "udp", inodes)[0] == Bound("udp", "127.0.0.1", 16572)
    assert all(isinstance(b, Bound) for b in listening())  # this process's own tables read


def test_the_pipe_codec() -> None:
    rows, stamps = np.arange(6.0).reshape(3, 2), np.array([1.0, 2.0, 3.0])
    stream = io.BytesIO(wire.frame({"stream": STREAM}) + wire.frame(wire.chunk_message(rows, stamps)))
    assert wire.read(stream) == {"stream": STREAM}
    got_rows, got_stamps = wire.chunk_arrays(wire.read(stream), 2)
    assert np.array_equal(got_rows, rows) and np.array_equal(got_stamps, stamps)
    assert wire.read(stream) is None
    with pytest.raises(wire.WireError, match="do not match"):
        wire.chunk_message(rows, stamps[:2])
    with pytest.raises(wire.WireError, match="channels"):
        wire.chunk_arrays(wire.chunk_message(rows, stamps), 3)
    with pytest.raises(wire.WireError, match="bytes >"):
        wire.read(io.BytesIO((wire.MAX_MESSAGE + 1).to_bytes(4, "little")))
    with pytest.raises(wire.WireError, match="inside a message"):
        wire.read(io.BytesIO(wire.frame({"a": 1})[:-1]))
    with pytest.raises(wire.WireError, match="map"):
        wire.read(io.BytesIO(b"\x01\x00\x00\x00\x05"))


def test_the_loopback_configuration_file_is_removed_when_the_process_ends(tmp_path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "LSLAPICFG"} | {"TMPDIR": str(tmp_path)}
    code = ("from eyehil.emulator.device.lsl.library import use_loopback_config; import os; "
            "p = use_loopback_config(); print(p); print(open(p).read() != '' and os.environ['LSLAPICFG'] == p)")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    path, written = done.stdout.split("\n")[:2]
    assert written == "True" and Path(path).parent == tmp_path  # it was there while the process ran
    assert list(tmp_path.iterdir()) == []  # and is gone after
