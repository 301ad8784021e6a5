"""The PsychoPy tests: real ioHub eye-tracker backends, unmodified, in PsychoPy's own environment (see
psychopy_helpers); a leak check on every test."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from leaks import leak_check

sys.path.insert(0, str(Path(__file__).parents[1] / "opengaze"))  # opengaze_helpers


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail the test if it leaves an emulator thread, server or listening socket behind."""
    with leak_check("eyehil", listening=True):
        yield
