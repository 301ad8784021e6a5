"""Issue 11 regressions on the device side: peer numbers range-checked, bounded queues, solves that never block.

Everything runs on simulated time (`ManualClock`) or explicit events: no wall-clock deadline decides a result
(a thread join has a generous deadline only so that a regression fails instead of hanging the suite).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
from device_helpers import CoreHost, core_device

from eyehil.emulator.device.clock import ManualClock
from eyehil.emulator.device.gaze import MAX_TIME_US, Kind, Timeline, clamp_time_us
from eyehil.emulator.device.links.base import MAX_INBOX_BYTES, MAX_REPLY_BACKLOG, LinkRunner
from eyehil.emulator.device.solver import FeatureSolver, InThreadSolves, SolveQueue
from eyehil.emulator.device.subject import Subject
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.scene import load_scene
from eyehil.protocols import Ack, Features, GetInfo, Start, Stimulus
from eyehil.protocols.native import encode

GENEROUS_S = 60.0  # only bounds a hang; never decides a result


class GatedSolver(FeatureSolver):
    """A FeatureSolver with a cheap closed-form `solve`; single-point solves (fixations) wait for `gate`."""

    def __init__(self) -> None:
        super().__init__(normative_eye("navarro"), load_scene("guestrin2006"))
        self.gate = threading.Event()
        self.single_solves = 0

    def solve(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        if len(xy) == 1:
            self.single_solves += 1
            if not self.gate.wait(GENEROUS_S):
                raise RuntimeError("gate never opened")
        base = np.concatenate([xy, xy**2 / 100.0], axis=1)  # smooth, non-linear: interpolation != exact
        values = np.tile(base[:, None, :1], (1, self.n_eyes, self.n_channels))
        values[..., 1] = base[:, None, 1]
        values[..., 2] = base[:, None, 2] + base[:, None, 3]
        return values


@pytest.fixture
def gated():
    solver = GatedSolver()
    yield solver
    solver.gate.set()


def _subject(solver: GatedSolver, **kw) -> Subject:
    solver.gate.set()  # the start point is solved at construction
    subject = Subject(solver, solves=InThreadSolves, **kw)  # the gate is an Event of this process
    solver.gate.clear()
    return subject


# --- finding 1: a peer's timestamp or position never stops the subject -------------------------------------------
@pytest.mark.parametrize("t", [10**19, 2**63, 10**300, 9.2e12 * 1e6, 1e300, -1e308, -(10**30)])
def test_look_at_with_absurd_times_keeps_the_subject_working(gated: GatedSolver, t) -> None:
    subject = _subject(gated)
    try:
        effect = subject.look_at((10.0, 20.0), t)
        assert 0 <= effect <= MAX_TIME_US + 10**7
        obs = subject.observe(np.array([1_000, 2_000, 3_000], np.int64))
        assert obs.values.shape[0] == 3
    finally:
        gated.gate.set()  # the solve it started may finish: closing waits for a solve under way in this process
        subject.close()


@pytest.mark.parametrize("xy", [(float("nan"), 0.0), (0.0, float("inf")), (1e308, 0.0), (-1e7, 5.0)])
def test_look_at_with_absurd_positions_is_refused_and_counted(gated: GatedSolver, xy) -> None:
    subject = _subject(gated)
    try:
        before = list(subject.timeline.pieces)
        subject.look_at(xy, 1_000)
        assert subject.targets_refused == 1 and subject.timeline.pieces == before
    finally:
        subject.close()


def test_timeline_clamps_times() -> None:
    line = Timeline((1.0, 2.0))
    xy, kind = line.evaluate(np.array([-5, 0, 2**62 + 5], dtype=np.int64))
    assert np.isfinite(xy).all() and (kind == Kind.HOLD).all()
    assert line.cut(10**40) == (1.0, 2.0)
    assert clamp_time_us(1e300) == MAX_TIME_US and clamp_time_us(-3) == 0
    with pytest.raises(ValueError):
        clamp_time_us(float("nan"))


# --- finding 3: solves are coalesced and never block the device thread --------------------------------------------
def test_solve_queue_coalesces_to_the_latest_target(gated: GatedSolver) -> None:
    queue = SolveQueue(gated)
    try:
        assert queue.wait(None, GENEROUS_S)  # the grid (many points: not gated)
        for i in range(100):
            queue.request((float(i), 1.0))
        gated.gate.set()
        assert queue.wait((99.0, 1.0), GENEROUS_S)
        assert queue.solved <= 2 and queue.coalesced >= 98
        assert gated.has_exact((99.0, 1.0))
    finally:
        queue.close()


def test_observe_interpolates_while_the_exact_solve_runs(gated: GatedSolver) -> None:
    subject = _subject(gated)
    try:
        subject.look_at((50.0, -30.0), 0)
        assert subject._solves.wait(None, GENEROUS_S)  # grid built, the exact solve is held by the gate
        times = np.arange(1_000_000, 1_010_000, 1_000, dtype=np.int64)  # long after the saccade
        obs = subject.observe(times)  # must return although the solve cannot finish
        expected = gated.field(np.array([[50.0, -30.0]]))[0]
        np.testing.assert_allclose(obs.values[0], expected)
        assert subject.interpolated_holds == len(times)
        gated.gate.set()
        assert subject._solves.wait((50.0, -30.0), GENEROUS_S)
        exact = subject.observe(times + 10_000).values[0]
        np.testing.assert_allclose(exact, gated.solve(np.array([[50.0, -30.0]]))[0])
        assert not np.allclose(exact, expected)
    finally:
        subject.close()


def test_stimulus_flood_while_streaming_is_acked_without_waiting_for_solves(gated: GatedSolver) -> None:
    """100 STIMULUS at new positions while streaming, with every exact solve held: all ACKs come, samples go on."""
    core = core_device()
    core.subject.close()
    core.subject = _subject(gated)
    core.camera.subject = core.subject
    clock: ManualClock = core.clock
    host = CoreHost(core)
    done = threading.Event()

    def scenario() -> None:
        host.send(Start())
        host.read()
        for i in range(100):
            seq = host.send(Stimulus(i, 100.0 + i, 120.0, 1))
            (reply,) = [m for m in host.messages() if not isinstance(m, Features)]
            assert isinstance(reply, Ack) and reply.acked_seq == seq
            clock.now += 4_000
            core.poll()
        done.set()

    worker = threading.Thread(target=scenario, daemon=True)
    worker.start()
    worker.join(GENEROUS_S)
    try:
        assert done.is_set(), "the device thread blocked on a fixation solve"
        assert core.status().samples_sent > 0
        assert core.subject._solves.solved + 1 <= gated.single_solves <= 2
    finally:
        gated.gate.set()
        core.close()


# --- finding 2: a host that floods commands and never reads cannot grow the device ----------------------------------
def test_reply_flood_without_reading_is_bounded_and_counted() -> None:
    core = core_device()
    try:
        wire = b"".join(_encoded(GetInfo(), seq) for seq in range(20_000))
        core.feed(wire)
        assert core.pending <= core.max_output_bytes + 256 * 1024 + 64 * 1024 + 200
        assert core.replies_dropped > 10_000
        core.read_available()
        host = CoreHost(core)
        host.send(GetInfo())
        assert len(host.messages()) == 1  # and it still answers
    finally:
        core.close()


def _encoded(message, seq: int) -> bytes:
    return encode(message, seq, 0)


class StuckLink:
    """A DeviceLink whose host never reads: everything sent stays in its backlog (counted, not kept)."""

    name = url = "stuck"
    connected = True

    def __init__(self) -> None:
        self.queued = 0
        self.receive = self.reset = None

    def attach(self, receive, reset) -> None:
        self.receive, self.reset = receive, reset

    def send(self, data: bytes) -> None:
        self.queued += len(data)

    def backlog(self) -> int:
        return self.queued

    def close(self) -> None:
        pass


def test_runner_inbox_is_bounded_when_the_host_never_reads() -> None:
    core = core_device()
    link = StuckLink()
    runner = LinkRunner(core, link)
    runner.start()
    try:
        request = _encoded(GetInfo(), 1)
        for _ in range(200_000):
            link.receive(request)
        assert runner.inbox_bytes <= MAX_INBOX_BYTES
        assert runner.counters["input_dropped_bytes"] > 0
        assert link.queued < MAX_REPLY_BACKLOG + 4096 + core.max_output_bytes + 64 * 1024
    finally:
        runner.close()
