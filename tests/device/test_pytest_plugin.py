"""The pytest plugin, used as a user would: a separate pytest run on a test file that asks for its fixtures."""

from __future__ import annotations

import subprocess
import sys

USER_TESTS = '''
import pytest
from eyehil.drivers.client import open_tracker


def test_default_device_on_a_pty(eyehil_url, eyehil_emulator):
    assert eyehil_url.startswith("/dev/pts/")
    with open_tracker(eyehil_url) as tracker:
        assert tracker.info.led_count == 2
        tracker.start()
        assert tracker.read_sample().eyes
    assert eyehil_emulator.core.status().samples_sent > 0


@pytest.mark.eyehil(scene="blignaut2014", link="tcp", rate_hz=120)
def test_marker_options(eyehil_url, eyehil_geometry, eyehil_options):
    assert eyehil_url.startswith("socket://127.0.0.1:") and eyehil_geometry.read_text().startswith("#")
    with open_tracker(eyehil_url) as tracker:
        assert (tracker.info.sample_rate_hz, tracker.info.camera_width) == (120, 1600)
'''


def test_plugin_serves_user_tests(tmp_path) -> None:
    (tmp_path / "test_user.py").write_text(USER_TESTS)
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:eyehil",
           "-p", "eyehil.emulator.device.pytest_plugin", "test_user.py"]
    result = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "2 passed" in result.stdout
