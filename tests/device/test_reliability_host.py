"""Issue 11 regressions on the host side: bounded allocations, replies matched by what they answer, deadlines,
duplicates never delivered, fresh sessions. Scripted peers and explicit events; no wall-clock result."""

from __future__ import annotations

import os
import socket
import threading

import pytest
from device_helpers import CoreHost, core_device

from eyehil.drivers import wire as wire_module
from eyehil.drivers.client import MAX_DRAIN_BYTES, Tracker
from eyehil.drivers.errors import LinkError, TrackerError, TrackerTimeoutError
from eyehil.drivers.links.tcp import TcpPort
from eyehil.drivers.wire import Wire
from eyehil.protocols import (
    Ack,
    Configure,
    DeviceState,
    EyeFeatures,
    EyeSelect,
    Features,
    FrameChunk,
    GetInfo,
    Ping,
    Pong,
    PupilFlags,
    Start,
)
from eyehil.protocols.enums import Eye, PixelFormat
from eyehil.protocols.native import HOST_TYPES, encode
from eyehil.protocols.stream import NativeReceiver, Received

GENEROUS_S = 60.0


class ScriptedDevice:
    """A SerialLike whose device answers each host command with `answer(header, message) -> [messages]`."""

    def __init__(self, answer, preload: bytes = b"") -> None:
        self.answer, self.timeout = answer, 0.0
        self.rx = NativeReceiver(accept=HOST_TYPES)
        self.out = bytearray(preload)
        self.seq = 0

    def write(self, data: bytes) -> int:
        for event in self.rx.feed(data):
            if isinstance(event, Received):
                for message in self.answer(event.header, event.message):
                    self.out += encode(message, self.seq, 1_000)
                    self.seq += 1
        return len(data)

    def read(self, size: int = 1) -> bytes:
        data = bytes(self.out[:size])
        del self.out[:size]
        return data

    def close(self) -> None:
        pass


def _info():
    core = core_device()
    try:
        return core.info
    finally:
        core.close()


INFO = _info()


def _honest(header, message):
    if isinstance(message, GetInfo):
        return [INFO]
    if isinstance(message, Ping):
        return [Pong(message.nonce, header.timestamp_us, 5)]
    if type(message).__name__ == "GetStatus":
        from eyehil.protocols import Status

        return [Status()]
    return [Ack(header.seq, header.msg_type)]


# --- finding 6: replies carry what they answer ----------------------------------------------------------------------
def test_an_ack_in_place_of_device_info_is_a_tracker_error_not_an_attribute_error() -> None:
    def liar(header, message):
        return [Ack(header.seq, header.msg_type)] if isinstance(message, GetInfo | Ping) else _honest(header, message)

    with pytest.raises(TrackerTimeoutError):
        Tracker(ScriptedDevice(liar), response_timeout=0.01, retries=1)


def test_replies_left_for_a_departed_host_do_not_answer_the_next_one() -> None:
    stale = b"".join(encode(Ack(seq, 0x03), 90_000 + seq, 0) for seq in range(5_000))
    stale += b"".join(encode(INFO, 95_000 + k, 0) for k in range(3))
    tracker = Tracker(ScriptedDevice(_honest, preload=stale), response_timeout=GENEROUS_S)
    assert tracker.info == INFO
    assert tracker.stats.stale_replies >= 5_000


def test_sessions_start_at_random_sequence_numbers() -> None:
    bases = {Tracker(ScriptedDevice(_honest), handshake=False).wire.seq for _ in range(8)}
    assert len(bases) == 8


def test_an_ack_for_our_seq_but_another_type_is_not_taken() -> None:
    def wrong_type(header, message):
        return [Ack(header.seq, 0x06)] if isinstance(message, Configure) else _honest(header, message)

    tracker = Tracker(ScriptedDevice(wrong_type), response_timeout=0.01, retries=0)
    with pytest.raises(TrackerTimeoutError):
        tracker.configure(rate_hz=250)
    assert tracker.stats.mismatched_replies == 1


# --- finding 5: the host allocates only plausible images ------------------------------------------------------------
def test_a_huge_frame_chunk_claim_is_refused_without_allocating() -> None:
    chunk = FrameChunk(1, Eye.RIGHT, PixelFormat.MONO16, 16384, 16384, 0, 0, 0, 1, 0, b"\x00" * 8)
    wire = Wire(ScriptedDevice(_honest, preload=encode(chunk, 1, 0)))
    wire.pump(0)
    assert wire.stats.images_refused == 1 and not wire.assembler._partial and not wire.images


# --- finding 11: duplicates never reach the application; loss counted once -----------------------------------------
def _features(frame_id: int) -> Features:
    eye = EyeFeatures(Eye.RIGHT, PupilFlags.DETECTED, 1.0, 2.0, 3.0, 2.0, 0.0, 1.0)
    return Features(frame_id, (eye,))


def test_duplicated_and_reordered_samples_are_dropped_and_loss_is_exact() -> None:
    frames = {seq: encode(_features(seq), seq, seq) for seq in range(100)}
    order = list(range(100))
    order.insert(10, 9)  # duplicate of 9
    order[20], order[21] = order[21], order[20]  # 20 arrives after 21 (late: lost to the application)
    order.remove(50)  # lost
    wire = Wire(ScriptedDevice(_honest, preload=b"".join(frames[s] for s in order)))
    while wire.pump(0):
        pass
    ids = [s.frame_id for s in wire.samples]
    assert len(ids) == len(set(ids)) and ids == sorted(ids)
    assert wire.stats.duplicates_dropped == 2
    assert wire.stats.lost_frames == 100 - len(ids) == 2  # 20 (late) and 50


def test_samples_nobody_read_are_discarded_and_the_next_one_marks_the_gap(monkeypatch) -> None:
    """A full sample buffer discards its oldest; the sample left first carries their gaps (frame ids, link losses),
    so a recording of what the application read still marks every gap."""
    monkeypatch.setattr("eyehil.drivers.wire.MAX_BUFFERED_SAMPLES", 5)
    seqs = [s for s in range(30) if s not in (3, 4, 12)]  # 3, 4 and 12 lost on the link
    wire = Wire(ScriptedDevice(_honest, preload=b"".join(encode(_features(s), s, s) for s in seqs)))
    while wire.pump(0):
        pass
    got = list(wire.samples)
    assert [s.frame_id for s in got] == [25, 26, 27, 28, 29]
    assert wire.stats.samples_overflowed == len(seqs) - 5
    first = got[0]
    assert first.skipped_before == 25  # frames 0-24: the reader saw none of them
    assert first.lost_before == 3  # 3, 4 and 12: the link's losses before it are not forgotten
    assert all(s.skipped_before == 0 and s.lost_before == 0 for s in got[1:])


class FailsAfterOneByte:
    """A link whose waiting read returns one byte and whose next read fails (a disconnect mid-read)."""

    timeout = 0.0

    def __init__(self, data: bytes) -> None:
        self.data, self.reads = data, 0

    def read(self, size: int = 1) -> bytes:
        self.reads += 1
        if self.reads == 1:
            return b""  # nothing waiting: the wire blocks for one byte
        if self.reads == 2:
            return self.data[:1]
        raise ConnectionResetError("gone")

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


def test_a_read_that_fails_after_one_byte_loses_nothing() -> None:
    """The byte that arrived before the failure is decoded (here: the delimiter that completes a sample)."""
    frame = encode(_features(7), 7, 0)
    wire = Wire(FailsAfterOneByte(frame[-1:]))
    wire.receiver.feed(frame[:-1])  # the frame so far, all but its delimiter
    with pytest.raises(LinkError):
        wire.pump(0.01)
    assert [s.seq for s in wire.samples] == [7]


# --- finding 9: every blocking host call has a deadline ---------------------------------------------------------------
class EndlessLink:
    """A link that always has another sample to read."""

    timeout = 0.0

    def __init__(self) -> None:
        self.seq = 0
        self.read_bytes = 0

    def read(self, size: int = 1) -> bytes:
        data = encode(_features(self.seq), self.seq, 0)
        self.seq += 1
        self.read_bytes += len(data)
        return data

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


def test_drain_returns_from_a_link_that_never_pauses() -> None:
    link = EndlessLink()
    tracker = Tracker(link, handshake=False)
    result: list = []
    worker = threading.Thread(target=lambda: result.append(tracker.drain(max_s=1e9, max_bytes=20_000)), daemon=True)
    worker.start()
    worker.join(GENEROUS_S)
    assert result and result[0], "drain() did not return"
    assert 20_000 <= link.read_bytes < 20_000 + 100
    assert MAX_DRAIN_BYTES < 64 * 1024 * 1024  # the default is bounded too


class _FourKilobytesAtATime:
    """A link read without waiting that always has 4 kB more, like a pseudo-terminal fed by a fast device."""

    timeout = 0.0

    def __init__(self) -> None:
        self.asked: list[int] = []

    def fileno(self) -> int:
        return -1

    def read_now(self, size: int) -> bytes:
        self.asked.append(size)
        return bytes(min(size, 4096))  # delimiters only: nothing to decode

    def write(self, data: bytes) -> int:
        return len(data)


def test_a_pump_gathers_at_most_drain_bytes_asking_at_most_a_chunk_a_read() -> None:
    link = _FourKilobytesAtATime()
    wire = Wire(link)
    assert wire.pump(0) == wire_module.DRAIN
    assert max(link.asked) == wire_module.CHUNK and sum(min(a, 4096) for a in link.asked) == wire_module.DRAIN


def test_tcp_write_to_a_peer_that_never_reads_raises() -> None:
    server = socket.create_server(("127.0.0.1", 0))
    port = TcpPort("127.0.0.1", server.getsockname()[1], write_timeout=0.2)
    peer, _ = server.accept()
    try:
        with pytest.raises(TimeoutError):
            for _ in range(10_000):
                port.write(b"\x00" * 65536)
    finally:
        port.close()
        peer.close()
        server.close()


# --- finding 7: a new connection's session is fresh -------------------------------------------------------------------
def test_a_new_connection_finds_the_device_idle_and_configurable() -> None:
    core = core_device()
    try:
        host = CoreHost(core)
        host.send(Start())
        core.clock.now += 100_000
        core.poll()
        assert core.pending > 0
        core.connection_reset()
        assert core.state is DeviceState.IDLE and core.pending == 0
        host = CoreHost(core)
        seq = host.send(Configure(2, 500, EyeSelect.RIGHT))
        assert host.messages() == [Ack(seq, Configure.TYPE)]
    finally:
        core.close()


def test_tracker_error_tree_covers_reply_mismatch() -> None:
    assert issubclass(TrackerTimeoutError, TrackerError)


class DrainedThenGone:
    """A link read without waiting (`read_now`): one frame's bytes, then the link fails."""

    timeout = 0.0

    def __init__(self, data: bytes) -> None:
        self.data, self.reads = data, 0
        self._r, self._w = os.pipe()

    def fileno(self) -> int:
        return self._r

    def read_now(self, size: int) -> bytes:
        self.reads += 1
        if self.reads == 1:
            return self.data
        raise ConnectionResetError("gone")

    def read(self, size: int = 1) -> bytes:
        raise AssertionError("a link with read_now is drained with it")

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        os.close(self._r)
        os.close(self._w)


def test_a_drained_link_that_fails_after_a_frame_loses_nothing() -> None:
    link = DrainedThenGone(encode(_features(9), 9, 0))
    wire = Wire(link)
    try:
        with pytest.raises(LinkError):
            wire.pump(0.01)
        assert [s.seq for s in wire.samples] == [9] and link.reads == 2
    finally:
        link.close()


def test_the_host_drains_raw_ports_without_waiting_and_reads_wrappers_through_their_read(tmp_path) -> None:
    """pyserial's posix ports and the TCP port are read without a wait between reads; a wrapper (spy, faults) is read
    through its own `read`, so it sees every byte."""
    import serial

    from eyehil.drivers.links.fault import FaultLink, FaultSpec
    from eyehil.drivers.links.tcp import TcpPort
    from eyehil.drivers.wire import _reader
    from eyehil.emulator.device.links.pty import PtyLink

    link = PtyLink()
    link.attach(lambda data: None, lambda: None)
    port = serial.Serial(link.url, timeout=0)
    try:
        link.send(b"\x01" * 50_000)
        read = _reader(port)
        got = b""
        while len(got) < 50_000:
            got += read(65536)
        assert got == b"\x01" * 50_000 and read(65536) == b""
        assert _reader(FaultLink(port, FaultSpec(drop=0.5))) is None
    finally:
        port.close()
        link.close()
    assert _reader(TcpPort.__new__(TcpPort)) is not None
