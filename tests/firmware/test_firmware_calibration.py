"""Calibration through the C firmware: the host shows targets (STIMULUS, forwarded by the firmware to the simulated
subject), collects FEATURES, fits and validates; the validation errors equal those of the same calibration through
the Python `VirtualTracker` on the same eye within 0.05 deg (Guestrin with 2 LEDs in guestrin2006, Blignaut with 1
LED and both eyes in blignaut2014); they agree to 1e-6 deg, since both stream the same float32 features. The
firmware runs in real time, so each run takes about 7 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.drivers.calibration import Plan, calibrate
from eyehil.drivers.client import open_tracker
from eyehil.drivers.setup_file import load_geometry
from eyehil.emulator.device.setup_file import write_geometry
from eyehil.emulator.scene import load_scene

EYES, EYE = "published", 17  # the eye tests/device/test_calibration_e2e.py uses (the most sensitive to rounding)
RATE_HZ = 500
TOLERANCE_DEG = 0.05


@pytest.mark.parametrize("scene_name, method", [("guestrin2006", "guestrin"), ("blignaut2014", "blignaut")])
def test_calibration_through_the_firmware_matches_the_python_device(rig, tmp_path, scene_name: str,
                                                                    method: str) -> None:
    geometry = load_geometry(write_geometry(load_scene(scene_name), tmp_path / "geometry.toml")).geometry
    plan = Plan.default(geometry.screen, settle_s=0.4, collect_s=0.05)
    with open_tracker(rig(scene=scene_name, eyes=EYES, eye=EYE, clock="fast").url) as tracker:  # lockstep: none lost
        firmware = calibrate(tracker, geometry, method, plan, rate_hz=RATE_HZ)
    with open_tracker(f"loop://?scene={scene_name}&eyes={EYES}&eye={EYE}&clock=fast") as tracker:
        python = calibrate(tracker, geometry, method, plan, rate_hz=RATE_HZ)
    assert all(len(f) == 25 for f in firmware.fixations)  # 0.05 s at 500 Hz, nothing lost
    np.testing.assert_allclose(firmware.errors_deg, python.errors_deg, atol=TOLERANCE_DEG)
    # Both devices send the same float32 features (the fixations are exact solutions), so in fact they agree exactly.
    np.testing.assert_allclose(firmware.errors_deg, python.errors_deg, atol=1e-6)
    assert firmware.mean_error_deg < 1.0
