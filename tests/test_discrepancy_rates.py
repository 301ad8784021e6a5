"""The discrepancy workflow's blind-trial rates over the whole catalogue, against issue 18's targets, for both
presets as recordings and as tables: Guestrin 2006 and Blignaut 2014 measured as from recordings (the gaze
conditions and every feature condition), and each as per-subject gaze-error tables.

In each setting every effect of the experiment's catalogue (`trials.catalogue`) is hidden once at a random strength
(`trials.draw`: 40-90 % of the way from neutral to a bound; glint occlusion's radius over the middle 80 % of its range)
in data from 20 hidden eyes of a Rozema 2011 draw; 10 random pairs; 4 negative controls; 4 effects hidden and removed,
with their twins (`Effect.twins`, `trials.outside`), from the catalogue the workflow may choose from. The workflow runs
blind on model eyes of their own (a Rozema draw, 16 search eyes, 20 show eyes), the settings of docs/discrepancy.md's
rates. The trials are seeded: the rates are those of docs/discrepancy.md ("Rates now"), and a change of the workflow
that moves one shows here. A rate a setting does not reach is a strict xfail saying why (`SHORT`): reaching it fails the
test, so the record is kept true. Up to 20 minutes of CPU a setting (Blignaut 2014 tables: 5), run in two processes
(`trials.run_trials`), whose trials share each process's memo of evaluated points (`trials.memo`).
"""

from __future__ import annotations

import pytest
from blind_rates import keep

from eyehil.analysis.discrepancy.trials import TARGETS, catalogue, met, rates, run_trials

COMMON = {"search_eyes": 16, "show_eyes": 20, "hidden_eyes": 20, "seed": 0, "model": "rozema"}
SETTINGS = {
    "guestrin2006-recordings": {"experiment": "guestrin2006", "features": True},
    "blignaut2014-recordings": {"experiment": "blignaut2014", "features": True},
    "guestrin2006-tables": {"experiment": "guestrin2006", "features": False},
    "blignaut2014-tables": {"experiment": "blignaut2014", "features": False},
}
COUNTS = {"pair": 10, "negative": 4, "outside": 4}

#: (setting, rate) -> why the setting misses the issue's target (docs/discrepancy.md, "Rates now"; docs/blind-trials.md)
SHORT: dict[tuple[str, str], str] = {
    ("blignaut2014-recordings", "singles_named"): (
        "9 of 17, 9 of the 13 visible: at one head position the corneal index, tangential distortion, camera pose "
        "and astigmatism open no gap and the pupil ellipse no significant one; the two decentrations are named as "
        "each other's twin; glint occlusion, which acts only on eyes whose glint meets the pupil's edge, is 'none "
        "explains': the model eyes hold fewer such eyes than the hidden ones, and its fit wants a bias beyond 1 "
        "(radius 7.2 px fitted, 7.6 hidden; feature noise added, glint occlusion its rival)"),
    ("blignaut2014-recordings", "pairs_in_order"): (
        "2 of 10, 2 of the 5 whose two effects are visible: one effect of the pair is invisible at one head position "
        "in 5; of the other 3, one names the larger alone (a screen position beside an astigmatism: D 40.1 over 32 "
        "terms after it, goodness of fit p 0.18, so no round 2, against 29.6 with both at their hidden values), one "
        "a tilted cornea for a decentred pupil, and one a lens distortion for a camera pose beside glint occlusion"),
    ("blignaut2014-recordings", "outside_none_explains"): (
        "2 of 4: the corneal index opens no gap ('no gap'); a decentred pupil, removed with its twin, is explained by "
        "a tilted cornea, its near-mimic at one head position (0.5 spreads between eyes in its worst condition)"),
    ("blignaut2014-recordings", "shrink_70"): (
        "10 of 11: a lens distortion (k1 2.67, fitted 2.81 +- 0.27) shrinks the show eyes' D from 141.7 to 43.8, "
        "69 %, against a no-effect floor of about 35"),
    ("guestrin2006-tables", "singles_named"): (
        "16 of 21, 16 of the 19 visible: in two mean errors per head position feature noise and head jitter are "
        "named as fixation error (per-fixation scatter alike) and a decentred pupil as its twin, the decentred "
        "cornea; the corneal index and the pupil ellipse open no gap in gaze errors"),
    ("guestrin2006-tables", "pairs_in_order"): (
        "6 of 10, 6 of the 8 visible: a pupil shift, the head roll's mimic in gaze errors, is named beside a "
        "screen tilt, and the data prefer it (backfitted beside the tilt, D + 2k 28.6 against the roll's 31.9); an "
        "asphericity and a tangential distortion are both named, out of order: the fitted distortion alone leaves "
        "more of D than the asphericity alone, though alone in the hidden data it opens the larger gap, and the "
        "data prefer the fit (D 7.1 on the search eyes, 10.5 at the hidden values; p2 +0.007 against -0.025); 2 "
        "name the one visible effect beside the invisible corneal index"),
    ("guestrin2006-tables", "outside_none_explains"): (
        "2 of 4: feature noise is explained by fixation error, a pupil change by a pupil shift (without the pupil's "
        "size, its change is its centre's shift)"),
    ("blignaut2014-tables", "singles_named"): (
        "6 of 17, 6 of the 9 visible: the interpolating calibration absorbs the geometric effects, and in six "
        "configurations' mean errors at one head position 8 open no gap (corneal index, lens and tangential "
        "distortion, camera pose, LED and screen position, astigmatism, pupil ellipse); the decentred pupil and "
        "cornea raise D over all conditions but leave no condition significant ('no gap'); corneal asphericity "
        "leaves spread gaps after its own addition ('none explains')"),
    ("blignaut2014-tables", "pairs_in_order"): (
        "0 of 10, 0 of the 1 whose two effects are visible: 9 pairs hold an effect that opens no gap of its own "
        "(4 'no gap'; 5 name the visible effect alone, glint occlusion three times); the one left names fixation "
        "error (D alone 766) and not the decentred pupil beside it (24.6, against a floor of 16.5)"),
    ("blignaut2014-tables", "outside_none_explains"): (
        "1 of 4, 1 of the 3 visible: feature noise is explained by head jitter (per-fixation scatter alike in mean "
        "errors), a decentred pupil removed with its twin and the corneal index open no significant gap ('no gap')"),
}

#: setting -> rate -> hits the CI run of the 25th session's code measured (docs/blind-trials.md), for the rates whose
#: trial count is fixed. A strict xfail in `SHORT` catches a rate that reaches its target, not a count that falls
#: short further; `test_no_count_falls_below_its_record` does. `SLACK` trials below the record are let pass: another
#: machine's floating point may tip a trial that sits at a decision's boundary.
RECORD: dict[str, dict[str, int]] = {
    "guestrin2006-recordings": {"singles_named": 20, "pairs_in_order": 7, "outside_none_explains": 4},
    "blignaut2014-recordings": {"singles_named": 9, "pairs_in_order": 2, "outside_none_explains": 2},
    "guestrin2006-tables": {"singles_named": 16, "pairs_in_order": 6, "outside_none_explains": 2},
    "blignaut2014-tables": {"singles_named": 6, "pairs_in_order": 0, "outside_none_explains": 1},
}
SLACK = 1


@pytest.fixture(scope="module", params=list(SETTINGS))
def setting(request) -> str:
    return request.param


@pytest.fixture(scope="module")
def records(setting) -> list[dict]:
    settings = {**COMMON, **SETTINGS[setting]}
    kinds = {"single": len(catalogue(settings["experiment"])), **COUNTS}
    out = []
    for kind, count in kinds.items():
        out += list(run_trials(kind, range(count), jobs=2, **settings))
    return out


@pytest.fixture(scope="module")
def counts(request, setting, records) -> dict[str, list[int]]:
    measured = rates(records)
    keep(request.config, setting, measured)  # printed in the run's summary (tests/blind_rates.py)
    return measured


def _expect(request, setting: str, rate: str) -> None:
    if (setting, rate) in SHORT:
        request.applymarker(pytest.mark.xfail(strict=True, reason=SHORT[setting, rate]))


def _misses(records: list[dict], kind: str, key: str) -> list[str]:
    return [f"{r['index']}: {', '.join(r['hidden']) or 'nothing'} -> {r['outcome']} {r['named_effects']}"
            for r in records if r["kind"] == kind and not r[key]]


def test_every_effect_of_the_catalogue_is_hidden_once(setting, records) -> None:
    singles = sorted(r["hidden"][0].split("(")[0] for r in records if r["kind"] == "single")
    assert singles == sorted(catalogue(SETTINGS[setting]["experiment"]))


def test_single_hidden_effects_are_named(request, setting, records, counts) -> None:
    _expect(request, setting, "singles_named")
    hits, n = counts["singles_named"]
    assert met(counts)["singles_named"], (f"{hits} of {n} named, target {TARGETS['singles_named']:.0%}; misses: "
                                          + "; ".join(_misses(records, "single", "named")))


def test_pairs_are_named_in_the_order_of_their_sizes(request, setting, records, counts) -> None:
    _expect(request, setting, "pairs_in_order")
    hits, n = counts["pairs_in_order"]
    assert met(counts)["pairs_in_order"], (f"{hits} of {n} in order, target {TARGETS['pairs_in_order']:.0%}; misses: "
                                           + "; ".join(_misses(records, "pair", "in_order")))


def test_nothing_is_added_on_negative_controls(request, setting, records, counts) -> None:
    _expect(request, setting, "negatives_nothing_added")
    assert met(counts)["negatives_nothing_added"], _misses(records, "negative", "added_nothing")


def test_an_effect_outside_the_catalogue_is_not_explained(request, setting, records, counts) -> None:
    _expect(request, setting, "outside_none_explains")
    assert met(counts)["outside_none_explains"], [
        f"{r['hidden']} -> {r['outcome']} {r['named_effects']}" for r in records
        if r["kind"] == "outside" and r["outcome"] != "none explains"]


def test_named_effects_shrink_the_gap_by_70_percent(request, setting, records, counts) -> None:
    _expect(request, setting, "shrink_70")
    assert met(counts)["shrink_70"], [f"{r['hidden']}: {r['shrink']:.0%}" for r in records
                                      if r["kind"] in ("single", "pair") and r["named_effects"] and r["shrink"] < 0.7]


def test_hidden_parameters_lie_within_their_reported_uncertainty(request, setting, counts) -> None:
    _expect(request, setting, "covered")
    hits, n = counts["covered"]
    assert met(counts)["covered"], f"{hits} of {n} hidden parameters within the fit's 95 % interval"


def test_no_count_falls_below_its_record(setting, counts) -> None:
    fallen = {rate: f"{counts[rate][0]} of {counts[rate][1]}, recorded {hits}"
              for rate, hits in RECORD[setting].items() if counts[rate][0] < hits - SLACK}
    assert not fallen, f"fewer hits than recorded (less {SLACK} of slack): {fallen}"
