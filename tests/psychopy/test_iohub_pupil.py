"""PsychoPy ioHub with psychopy-eyetracker-pupil-labs, unmodified, in gaze mode against the Pupil Capture facade:
`runSetupProcedure` (Pupil Capture's calibration, started with `C`) returns EYETRACKER_OK, and the sample events
built from `gaze.3d.` and `surfaces.<name>` lie within 1 deg of the target the subject looks at."""

from __future__ import annotations

import msgpack
import zmq
from opengaze_helpers import angle_deg
from psychopy_helpers import Script, psychopy_python

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.pupil.server import PupilServer, ServerOptions
from eyehil.emulator.device.subject import Behaviour

TARGET = (0.3, 0.7)  # screen fractions, top-left origin
SETTLE_S = 0.5  # the subject's latency (0.05 s) and saccade, with a margin
RECORD_S = 2.0
SURFACE = "psychopy_iohub_surface"  # the backend's default surface name


def _show(port: int, target: tuple[float, float]) -> float:
    """Show the subject `target` now through Pupil Remote (`notify.eyehil.stimulus`); its onset (Pupil s)."""
    ctx = zmq.Context()
    try:
        req = ctx.socket(zmq.REQ)
        req.rcvtimeo = req.linger = 10_000
        req.connect(f"tcp://127.0.0.1:{port}")
        req.send_string("t")
        onset = float(req.recv_string())
        note = {"subject": "eyehil.stimulus", "topic": "notify.eyehil.stimulus",
                "norm_pos": [target[0], 1.0 - target[1]], "timestamp": onset}  # Pupil: origin bottom-left
        req.send_multipart([b"notify.eyehil.stimulus", msgpack.packb(note, use_bin_type=True)])
        assert req.recv_string() == "Message forwarded."
        req.close(linger=0)
        return onset
    finally:
        ctx.term()


def test_iohub_calibrates_and_reads_gaze_on_the_surface() -> None:
    psychopy_python()  # skip early, before a server starts
    subject = build_subject(DeviceOptions(scene="guestrin2006", behaviour=Behaviour(latency_s=0.05)))
    srv = PupilServer(subject, options=ServerOptions(port=0, surface_name=SURFACE, world_rate_hz=0)).start()
    script = None
    try:
        scene = srv.subject.solver.scene
        script = Script("iohub_pupil.py", srv.port, RECORD_S, SURFACE)
        result = script.line("CALIBRATION")
        assert result == script.line("OK"), script.tail()
        script.line("READY")
        onset = _show(srv.port, TARGET)
        script.send("go")
        script.line("DONE")
    finally:
        if script is not None:
            script.close()
        srv.close()
    settled = script.samples(after_s=onset + SETTLE_S)
    assert len(settled) >= 30, script.tail()
    for s in settled:
        assert angle_deg(scene, TARGET, tuple(s["gaze"])) < 1.0, s
