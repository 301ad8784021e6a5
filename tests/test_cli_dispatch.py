"""The `eyehil` dispatcher: cheap top-level help and version, one-line errors with their exit codes, Ctrl-C."""

from __future__ import annotations

import argparse
import subprocess
import sys
import types

import pytest

from eyehil import cli


def test_version_and_help_import_no_subcommand() -> None:
    code = ("import sys, contextlib, io\nfrom eyehil import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try: cli.main(['--help'])\n    except SystemExit: pass\n"
            "print(sorted(m for m in ('numpy', 'scipy', 'cv2', 'zmq', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    version = subprocess.run([sys.executable, "-m", "eyehil", "--version"], capture_output=True, text=True, check=True)
    assert version.stdout.startswith("eyehil ")


HEAVY = ("numpy", "scipy", "cv2", "zmq", "matplotlib", "aiohttp")


@pytest.mark.parametrize("command", sorted(cli.COMMANDS))
def test_a_subcommands_help_imports_nothing_heavy(command: str) -> None:
    """`eyehil CMD --help` builds CMD's parser (its module is imported) without numpy, scipy, OpenCV ...: the work's
    modules are imported inside the functions that run it, so a subcommand starts in a fraction of a second."""
    code = ("import sys, contextlib, io\nfrom eyehil import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            f"    try: cli.main([{command!r}, '--help'])\n    except SystemExit: pass\n"
            f"assert out.getvalue().startswith('usage: eyehil {command}'), out.getvalue()\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_parsers_copies_of_choices_match_their_sources() -> None:
    """The parsers repeat two lists of choices so as not to import their (heavy) modules; they must agree."""
    from eyehil.drivers import calibration
    from eyehil.drivers import cli as host_cli
    from eyehil.drivers.view import cli as view_cli
    from eyehil.drivers.view import session

    assert tuple(host_cli.METHODS) == tuple(calibration.METHODS)
    assert tuple(view_cli.STREAMS) == tuple(session.STREAMS)


def _fake_command(monkeypatch: pytest.MonkeyPatch, action) -> None:
    module = types.ModuleType("eyehil_test_fake_command")

    def register(sub: argparse._SubParsersAction) -> None:
        sub.add_parser("fake").set_defaults(func=lambda args: action())

    module.register = register  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(cli.COMMANDS, "fake", (f"{module.__name__}:register", "a test command"))


@pytest.mark.parametrize(("error", "code"), [
    (KeyboardInterrupt(), 130),
    (ValueError("--eyes: needs at least two eyes"), 2),
    (OSError(98, "Address already in use"), 1),
    (ConnectionRefusedError(111, "Connection refused"), 1),
])
def test_errors_are_one_line_with_their_exit_code(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                                  error: BaseException, code: int) -> None:
    def fail() -> None:
        raise error

    _fake_command(monkeypatch, fail)
    assert cli.main(["fake"]) == code
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("eyehil fake: ")


def test_a_programming_error_is_not_hidden(monkeypatch: pytest.MonkeyPatch) -> None:
    def fail() -> None:
        raise KeyError("bug")

    _fake_command(monkeypatch, fail)
    with pytest.raises(KeyError):
        cli.main(["fake"])
