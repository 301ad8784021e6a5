"""Start a command as a terminal would, for the tests that press Ctrl-C (SIGINT to its process group).

A shell without job control starts background commands with SIGINT ignored, and Python keeps an ignored SIGINT
ignored (no KeyboardInterrupt): a suite run as `bash .ci/run &` or under nohup would hand that to every command it
starts, and a Ctrl-C test would then test the runner, not eyehil. The command gets its own session (so the
signal reaches its whole process group and nothing else) and SIGINT's default disposition back.
"""

from __future__ import annotations

import signal
from typing import Any


def _sigint_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


#: keyword arguments for subprocess.Popen
AS_FROM_A_TERMINAL: dict[str, Any] = {"start_new_session": True, "preexec_fn": _sigint_default}
