"""The firmware under the memory and undefined-behaviour checkers.

- ASan + UBSan (``make sanitize``, every finding fatal): the codec unit tests against the golden vectors, the
  extractor unit tests, and the firmware (native and ISCAN, features and raw frames) fed 100,000 mutated
  command frames by `fuzz_firmware.c`, every frame it sends checked.
- valgrind (memcheck, errors and definite leaks fatal): the firmware in the loop from pixels, calibrated by
  the host driver with Guestrin's method through it, then stopped with SIGTERM.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from firmware_helpers import GOLDEN, SOURCES

from eyehil.drivers.calibration import Plan, calibrate
from eyehil.drivers.client import open_tracker
from eyehil.drivers.setup_file import load_geometry
from eyehil.emulator.device.setup_file import write_geometry
from eyehil.emulator.scene import load_scene

FUZZ_FRAMES = 100_000
VALGRIND = ("valgrind", "--error-exitcode=99", "--leak-check=full", "--errors-for-leak-kinds=definite",
            "--track-origins=yes", "--quiet")


def _sanitizers_work(tmp_path) -> bool:
    probe = tmp_path / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    result = subprocess.run(["cc", "-fsanitize=address,undefined", "-o", str(tmp_path / "probe"), str(probe)],
                            capture_output=True, check=False)
    return result.returncode == 0


def test_sanitizers_find_nothing(firmware_build, tmp_path) -> None:
    if not _sanitizers_work(tmp_path):
        pytest.skip("the C compiler cannot build with -fsanitize=address,undefined here")
    result = subprocess.run(["make", "-C", str(SOURCES), f"BUILD={tmp_path}", f"GOLDEN={GOLDEN}",
                             f"FUZZ_FRAMES={FUZZ_FRAMES}", "sanitize"], capture_output=True, text=True,
                            timeout=900, check=False)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-4000:]
    assert "test_codecs: 215 checks, 0 failed" in output and "test_extract: all checks passed" in output, output
    assert f"fuzz_firmware: {FUZZ_FRAMES} mutated command frames" in output and ", 0 malformed" in output, output
    assert "runtime error" not in output and "AddressSanitizer" not in output, output[-4000:]


def test_valgrind_clean_in_the_loop_from_pixels(rig, tmp_path) -> None:
    if shutil.which("valgrind") is None:
        pytest.skip("valgrind is not installed")
    geometry = load_geometry(write_geometry(load_scene("guestrin2006"), tmp_path / "geometry.toml")).geometry
    plan = Plan.default(geometry.screen, settle_s=0.4, collect_s=0.3)
    r = rig(camera="pixels", wrapper=VALGRIND, scene="guestrin2006", eyes="published", eye=3)
    with open_tracker(r.url, timeout=30.0, response_timeout=3.0) as tracker:
        result = calibrate(tracker, geometry, "guestrin", plan, rate_hz=30)
        status = tracker.status()
    assert status.samples_sent > 50 and np.isfinite(result.errors_deg).all()
    assert r.close() == 0, r.log.read_text()[-4000:]  # valgrind's status: 99 on any error or definite leak
