"""The blind trials' measured rates, kept per setting by tests/test_discrepancy_rates.py and printed in the run's
summary (tests/conftest.py), so that a CI log records what every setting measured, passed or not."""

from __future__ import annotations

import pytest

#: setting -> rate -> [hits, trials]
RATES = pytest.StashKey[dict]()


def keep(config: pytest.Config, setting: str, counts: dict[str, list[int]]) -> None:
    config.stash.setdefault(RATES, {})[setting] = counts


def summarise(terminalreporter, config: pytest.Config) -> None:
    rates = config.stash.get(RATES, {})
    if rates:
        terminalreporter.section("discrepancy blind-trial rates (hits of trials)")
        for setting, counts in rates.items():
            terminalreporter.write_line(f"{setting}: " + "; ".join(f"{k} {h} of {n}" for k, (h, n) in counts.items()
                                                                   if n))
