"""An output folder never looks complete when its run did not finish: `staged_folder(out)`.

A run writes into a hidden sibling, ``.NAME.partial-PID``; only when every file is written do they move into
`out` (a new `out` is the renamed sibling, one atomic step; into an existing `out` each file moves with an
atomic `os.replace`, replacing the earlier run's file of that name and leaving other files alone). On any
exception, Ctrl-C included, the sibling is removed and `out` stays as it was.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def check_output_folder(out: Path) -> Path:
    """`out` if a run can write there (absent, or a folder); ValueError naming it otherwise (before any work)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: exists and is not a folder")
    return out


@contextmanager
def staged_folder(out: Path) -> Iterator[Path]:
    """Yield the partial folder to write into; see the module docstring for what happens after."""
    out = check_output_folder(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.parent / f".{out.name}.partial-{os.getpid()}"
    shutil.rmtree(partial, ignore_errors=True)  # a leftover of a killed run of the same process id
    partial.mkdir()
    try:
        yield partial
        if not out.exists():
            partial.rename(out)
            return
        for path in sorted(partial.rglob("*")):
            target = out / path.relative_to(partial)
            if path.is_dir():
                target.mkdir(exist_ok=True)
            else:
                os.replace(path, target)
    finally:
        shutil.rmtree(partial, ignore_errors=True)
