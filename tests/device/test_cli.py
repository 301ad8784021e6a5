"""The subcommands, run in-process: emulate (device side), info, stream, calibrate, record (host side);
start-up and closed-port checks in a subprocess."""

from __future__ import annotations

import errno
import os
import socket
import subprocess
import sys

import pytest
from device_helpers import query

from eyehil.cli import main
from eyehil.drivers.recording import read_recording
from eyehil.emulator.device import cli as emulate_cli


@pytest.fixture
def geometry(tmp_path, capsys):
    path = tmp_path / "g.toml"
    assert main(["emulate", "--link", "tcp", "--duration", "0", "--scene", "blignaut2014",
                 "--write-geometry", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"geometry: {path}" in out and "url: socket://127.0.0.1:" in out
    return path


def test_emulate_on_a_pty_prints_its_path(capsys) -> None:
    assert main(["emulate", "--link", "pty", "--duration", "0", "--mode", "iscan", "--behaviour", "jitter=0.02"]) == 0
    assert "url: /dev/pts/" in capsys.readouterr().out


@pytest.mark.parametrize(("link", "expected"), [("pty", emulate_cli.LINK_SWITCH_INTERVAL_S), ("zmq", None)])
def test_a_native_link_runs_with_a_short_switch_interval_and_restores_it(link, expected, monkeypatch, capsys) -> None:
    before, seen = sys.getswitchinterval(), []
    monkeypatch.setattr(emulate_cli, "wait_for_stop", lambda *_: seen.append(sys.getswitchinterval()))
    assert main(["emulate", "--link", link, "--port", "0", "--duration", "0"]) == 0
    assert seen == [pytest.approx(before if expected is None else expected)] and sys.getswitchinterval() == before


def test_info_and_stream(capsys) -> None:
    url = f"loop://?{query(rate=100)}"
    assert main(["info", url]) == 0
    out = capsys.readouterr().out
    assert "eyehil virtual tracker" in out and "capabilities features, frames, roi" in out and "<" not in out
    assert main(["stream", url, "--duration", "0.2", "--every", "5"]) == 0
    out = capsys.readouterr().out
    assert out.count("right pupil") == 5 and "21 samples" in out


def test_calibrate(geometry, capsys) -> None:
    url = f"loop://?{query(scene='blignaut2014', rate=250)}"
    assert main(["calibrate", url, "--method", "blignaut", "--geometry", str(geometry), "--settle", "0.35",
                 "--collect", "0.02", "--gaze-seconds", "0.1"]) == 0
    captured = capsys.readouterr()
    out = captured.out
    assert out.count("validation target") == 4 and "mean validation error" in out and "gaze t=" in out
    assert "x_form (1 + x + y" in out and "{" not in out  # readable parameters, not a dict
    targets = [line for line in captured.err.splitlines() if line.startswith("eyehil calibrate: target ")]
    assert targets[-1].endswith(f"{len(targets)}/{len(targets)}") and len(targets) > 4  # progress on stderr
    assert main(["calibrate", url, "--method", "blignaut", "--geometry", str(geometry), "--settle", "0.35",
                 "--collect", "0.02", "--gaze-seconds", "0", "--quiet"]) == 0
    assert "target" not in capsys.readouterr().err


def test_calibrate_refuses_another_scenes_geometry(geometry, capsys) -> None:
    """Issue 17: a blignaut2014 geometry file against a guestrin2006 device calibrated without a word."""
    url = f"loop://?{query(scene='guestrin2006', rate=250)}"
    assert main(["calibrate", url, "--method", "guestrin", "--geometry", str(geometry), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "1600 x 1200 px camera with 1 LED(s), but the device has a 640 x 480" in err[0]


def test_record_with_targets(geometry, tmp_path, capsys) -> None:
    url = f"loop://?{query(scene='blignaut2014', rate=100)}"
    out_file = tmp_path / "run.jsonl"
    assert main(["record", url, "-o", str(out_file), "--duration", "0.5", "--targets", "2x2",
                 "--geometry", str(geometry), "--dwell", "0.2"]) == 0
    rec = read_recording(out_file)
    assert rec.complete and len(rec) == 51 and len(rec.targets) == 3
    assert "51 samples" in capsys.readouterr().out


def test_errors_are_reported_not_raised(capsys) -> None:
    assert main(["info", "nonsense://x"]) == 1
    assert "SchemeUnavailableError" in capsys.readouterr().err


def test_stream_through_injected_faults(capsys) -> None:
    url = f"loop://?{query(rate=500)}"
    spec = "drop=0.05,duplicate=0.05,seed=3,after=10"
    assert main(["stream", url, "--duration", "0.5", "--every", "100", "--fault", spec]) == 0
    out = capsys.readouterr().out
    assert "lost_frames" in out and "duplicates_dropped" in out


def _closed_port() -> int:
    """A loopback port nothing listens on (bound, never listening: a connection to it is refused)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.parametrize("command", ["info", "stream"])
def test_a_closed_port_is_one_line_naming_the_address(command: str) -> None:
    """Refused at once whatever --timeout says (600 s here; the subprocess gets far less), one line, exit 1, and
    the command never loaded the estimators or OpenCV on its way."""
    url = f"socket://127.0.0.1:{_closed_port()}"
    code = ("import sys\nfrom eyehil.cli import main\n"
            f"rc = main([{command!r}, {url!r}, '--timeout', '600'])\n"
            "print(rc, sorted(m for m in ('scipy', 'cv2', 'zmq', 'matplotlib') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "1 []"
    refused = f"[Errno {errno.ECONNREFUSED}] {os.strerror(errno.ECONNREFUSED)}"
    assert done.stderr.splitlines() == [f"eyehil {command}: LinkError: cannot open {url!r}: {refused}"]
