"""Servers that cannot listen say so in one line naming the link, the address and the reason, and exit 1.

Each test occupies a port with a socket it binds itself, then asks a link to listen there; out-of-range ports are
refused by argparse (exit 2). The leak check of this folder's conftest also proves that a failed start leaves no
thread, socket or pipe behind.
"""

from __future__ import annotations

import errno
import socket
from collections.abc import Iterator

import pytest

from eyehil.cli import main
from eyehil.emulator.device.links.listen import ListenError, check_port, create_server

UNASSIGNED = "192.0.2.1"  # TEST-NET-1 (RFC 5737): no interface of a test machine has it


@pytest.fixture
def taken() -> Iterator[int]:
    """A loopback port this test holds (listening), so that nothing else can bind it."""
    with socket.create_server(("127.0.0.1", 0)) as sock:
        yield sock.getsockname()[1]


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    return lines[0]


LINKS = ["tcp", "usbip", "opengaze", "zmq"]


def _needs(link: str) -> None:
    if link == "zmq":
        pytest.importorskip("zmq")


@pytest.mark.parametrize("link", LINKS)
def test_a_port_in_use(link: str, taken: int, capsys: pytest.CaptureFixture[str]) -> None:
    _needs(link)
    assert main(["emulate", "--link", link, "--port", str(taken), "--duration", "0"]) == 1
    expected = f"eyehil emulate: error: cannot listen on {link} 127.0.0.1:{taken}: address already in use"
    assert _one_line(capsys) == expected


@pytest.mark.parametrize("link", LINKS)
def test_an_address_of_no_interface(link: str, capsys: pytest.CaptureFixture[str]) -> None:
    _needs(link)
    assert main(["emulate", "--link", link, "--host", UNASSIGNED, "--duration", "0"]) == 1
    line = _one_line(capsys)
    assert line.startswith(f"eyehil emulate: error: cannot listen on {link} {UNASSIGNED}:")
    assert line.endswith(": cannot assign requested address")


@pytest.mark.parametrize("link", ["tcp", "zmq"])
def test_a_host_name_that_does_not_resolve(link: str, capsys: pytest.CaptureFixture[str]) -> None:
    _needs(link)
    assert main(["emulate", "--link", link, "--host", "no-such-host.invalid", "--duration", "0"]) == 1
    assert _one_line(capsys).startswith(f"eyehil emulate: error: cannot listen on {link} no-such-host.invalid:")


@pytest.mark.parametrize("option", ["--port=99999", "--port=-1", "--port=http", "--view-port=65536"])
def test_ports_out_of_range_are_usage_errors(option: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["emulate", "--link", "tcp", option, "--duration", "0"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"argument {option.split('=')[0]}: " in err.splitlines()[-1]


def test_the_library_refuses_ports_out_of_range_too() -> None:
    """libzmq would wrap 99999 around to another port, socket raises OverflowError: both become ValueError."""
    for port in (-1, 65536, 99999, True):
        with pytest.raises(ValueError, match="not a TCP port"):
            check_port("zmq", port)
    with pytest.raises(ValueError, match="tcp: port 70000"):
        create_server("tcp", "127.0.0.1", 70000)


def test_listen_error_is_an_oserror_with_the_errno(taken: int) -> None:
    with pytest.raises(ListenError) as error:
        create_server("tcp", "127.0.0.1", taken)
    assert isinstance(error.value, OSError) and error.value.errno == errno.EADDRINUSE


def test_the_view_page_on_a_port_in_use(taken: int, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("aiohttp")
    assert main(["view", "socket://127.0.0.1:9", "--port", str(taken), "--duration", "0"]) == 1
    expected = f"eyehil view: error: cannot listen on view http 127.0.0.1:{taken}: address already in use"
    assert _one_line(capsys) == expected


def test_emulate_view_on_a_port_in_use(taken: int, capsys: pytest.CaptureFixture[str]) -> None:
    """The device listens, the page cannot: one line, and the device is closed again (the leak check)."""
    pytest.importorskip("aiohttp")
    assert main(["emulate", "--link", "tcp", "--view", "--view-port", str(taken), "--duration", "0"]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "url: socket://127.0.0.1:" in captured.out
    assert captured.err.splitlines() == [
        f"eyehil emulate: error: cannot listen on view http 127.0.0.1:{taken}: address already in use"]
