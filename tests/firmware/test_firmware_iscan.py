"""The C firmware in ISCAN mode (``--mode iscan --rate HZ``), as the Python device has it
(`emulator.device.iscan`, `protocols.iscan`): 0x80 starts and 0x81 stops a stream of 10-byte records (0x4444,
pupil H, V, corneal reflection H, V in px x 10) at the fixed rate; other bytes are ignored; the first eye
the camera sees, LED 0. The records are plausible with the sensor's detector and, from raw frames, agree with the
ground truth of the frames served."""

from __future__ import annotations

import select
import time

import numpy as np
import pytest

from eyehil.drivers.links import open_link
from eyehil.protocols.iscan import IscanCommand, IscanParser

RATE_HZ = 120


def _records(link, count: int, timeout_s: float = 30.0) -> np.ndarray:
    parser, records = IscanParser(), np.empty((0, 4))
    deadline = time.monotonic() + timeout_s
    while len(records) < count and time.monotonic() < deadline:
        select.select([link.fileno()], [], [], 0.5)
        records = np.concatenate([records, parser.feed(link.read(4096))])
    assert len(records) >= count, f"{len(records)} ISCAN records within {timeout_s} s"
    return records


@pytest.mark.parametrize("camera", ["features", "pixels"])
def test_iscan_records_from_the_firmware(rig, camera: str) -> None:
    r = rig(camera=camera, args=("--mode", "iscan", "--rate", str(RATE_HZ)), scene="guestrin2006",
            eyes="published", eye=3)
    link = open_link(r.url, timeout=0.5)
    try:
        link.write(bytes([0x00, 0x42, IscanCommand.STOP]))  # ignored; STOP while stopped does nothing
        link.write(bytes([IscanCommand.START]))
        records = _records(link, 30)
        link.write(bytes([IscanCommand.STOP]))
    finally:
        link.close()
    assert np.all(records[:, 0] > 0) and np.all(records[:, 2] > 0)  # pupil H and reflection H found
    assert np.all(np.abs(records[:, 0] - records[:, 2]) < 30)  # px: the reflection lies near the pupil
    if camera == "pixels":
        # a snapshot: the sensor's server thread may still append frames the firmware asks for after STOP
        # (copying the deque in C holds the interpreter lock; iterating it in Python does not)
        served = [frame.truth for _, _, _, frame in list(r.sensor.truths)]
        truths = np.array([[*t.pupil_centre_px[0], *t.glint_px[0, 0]] for t in served])
        # every record is within 0.1 px (plus the wire's 0.05 px rounding) of some served frame's truth
        distance = np.abs(records[:, None, :] - truths[None, :, :]).max(-1).min(-1)
        assert np.all(distance < 0.2), distance
