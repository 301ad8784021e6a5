"""The discrepancy workflow's blind-trial rates over the whole catalogue, against issue 18's targets.

Every effect of the catalogue is hidden once at a random strength (`trials.draw`: 40-90 % of the way from neutral to
a bound), in data from 20 hidden eyes of a Rozema 2011 draw, measured as from recordings (the gaze conditions and
every feature condition); 10 random pairs; 4 negative controls; 4 effects hidden and removed, with their twins
(`Effect.twins`, `trials.outside`), from the catalogue the workflow may choose from. The workflow runs blind on
model eyes of their own (a Rozema draw, 16 search eyes, 20 show eyes), the settings of docs/discrepancy.md's
rates. The trials are seeded: the rates are those of the record in docs/discrepancy.md, and a change of the
workflow that moves one shows here. About 20 minutes of CPU, run in two processes (`trials.run_trials`).
"""

from __future__ import annotations

import pytest

from eyehil.analysis.discrepancy.trials import TARGETS, met, rates, run_trials
from eyehil.emulator import effects

SETTINGS = {"experiment": "guestrin2006", "search_eyes": 16, "show_eyes": 20, "hidden_eyes": 20, "seed": 0,
            "features": True, "model": "rozema"}
KINDS = {"single": len(effects.names()), "pair": 10, "negative": 4, "outside": 4}


@pytest.fixture(scope="module")
def records() -> list[dict]:
    out = []
    for kind, count in KINDS.items():
        out += list(run_trials(kind, range(count), jobs=2, **SETTINGS))
    return out


@pytest.fixture(scope="module")
def counts(records) -> dict[str, list[int]]:
    return rates(records)


def _misses(records: list[dict], kind: str, key: str) -> list[str]:
    return [f"{r['index']}: {', '.join(r['hidden']) or 'nothing'} -> {r['outcome']} {r['named_effects']}"
            for r in records if r["kind"] == kind and not r[key]]


def test_every_effect_of_the_catalogue_is_hidden_once(records) -> None:
    singles = sorted(r["hidden"][0].split("(")[0] for r in records if r["kind"] == "single")
    assert singles == sorted(effects.names())


def test_single_hidden_effects_are_named(records, counts) -> None:
    hits, n = counts["singles_named"]
    assert met(counts)["singles_named"], (f"{hits} of {n} named, target {TARGETS['singles_named']:.0%}; misses: "
                                          + "; ".join(_misses(records, "single", "named")))


def test_pairs_are_named_in_the_order_of_their_sizes(records, counts) -> None:
    hits, n = counts["pairs_in_order"]
    assert met(counts)["pairs_in_order"], (f"{hits} of {n} in order, target {TARGETS['pairs_in_order']:.0%}; misses: "
                                           + "; ".join(_misses(records, "pair", "in_order")))


def test_nothing_is_added_on_negative_controls(records, counts) -> None:
    assert met(counts)["negatives_nothing_added"], _misses(records, "negative", "added_nothing")


def test_an_effect_outside_the_catalogue_is_not_explained(records, counts) -> None:
    assert met(counts)["outside_none_explains"], [
        f"{r['hidden']} -> {r['outcome']} {r['named_effects']}" for r in records
        if r["kind"] == "outside" and r["outcome"] != "none explains"]


def test_named_effects_shrink_the_gap_by_70_percent(records, counts) -> None:
    assert met(counts)["shrink_70"], [f"{r['hidden']}: {r['shrink']:.0%}" for r in records
                                      if r["kind"] in ("single", "pair") and r["named_effects"] and r["shrink"] < 0.7]


def test_hidden_parameters_lie_within_their_reported_uncertainty(counts) -> None:
    hits, n = counts["covered"]
    assert met(counts)["covered"], f"{hits} of {n} hidden parameters within the fit's 95 % interval"
