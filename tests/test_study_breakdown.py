"""`eyehil study --anatomy full`: the change of the errors broken down by added anatomy (issue 13)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eyehil.analysis.study.breakdown import (
    COMPONENTS,
    GROUPS,
    added_parameters,
    component_changes,
    component_eyes,
    r_squared,
    run_anatomy,
    shapley_shares,
)
from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.report import write_outputs
from eyehil.analysis.study.summary import anatomy_breakdown, anatomy_summary, summarise_study
from eyehil.emulator.eye.anatomy import full_anatomy
from eyehil.emulator.eye.published import published_eyes

# -- the Shapley split of R^2 --------------------------------------------------------------------------


def test_orthogonal_groups_get_their_own_r_squared() -> None:
    """Uncorrelated groups: each share is that group's R^2 alone (no overlap to divide)."""
    n = 64
    t = np.arange(n)
    a = np.column_stack([np.cos(2 * np.pi * t / n), np.sin(2 * np.pi * t / n)])
    b = np.cos(2 * np.pi * 3 * t / n)[:, None]
    noise = np.cos(2 * np.pi * 7 * t / n) * 0.5
    y = 2.0 * a[:, 0] - a[:, 1] + 0.7 * b[:, 0] + noise
    shares = shapley_shares(y, {"a": a, "b": b})
    assert shares["a"] == pytest.approx(r_squared(y, a), abs=1e-12)
    assert shares["b"] == pytest.approx(r_squared(y, b), abs=1e-12)
    assert sum(shares.values()) == pytest.approx(r_squared(y, np.column_stack([a, b])), abs=1e-12)


def test_correlated_groups_split_the_overlap_and_sum_to_the_total() -> None:
    rng = np.random.default_rng(5)
    x1 = rng.standard_normal(200)
    x2 = 0.8 * x1 + 0.6 * rng.standard_normal(200)  # shares most of x1
    x3 = rng.standard_normal(200)  # unrelated to y
    y = x1 + x2 + 0.3 * rng.standard_normal(200)
    groups = {"x1": x1[:, None], "x2": x2[:, None], "x3": x3[:, None]}
    shares = shapley_shares(y, groups)
    total = r_squared(y, np.column_stack([x1, x2, x3]))
    assert sum(shares.values()) == pytest.approx(total, abs=1e-12)
    # two groups: share = (R2(alone) + R2(both) - R2(other alone)) / 2 (the same formula written out)
    two = shapley_shares(y, {"x1": groups["x1"], "x2": groups["x2"]})
    both = r_squared(y, np.column_stack([x1, x2]))
    expected = (r_squared(y, groups["x1"]) + both - r_squared(y, groups["x2"])) / 2
    assert two["x1"] == pytest.approx(expected, abs=1e-12)
    assert 0.0 <= shares["x3"] < 0.01 < shares["x1"]


def test_changes_and_interaction_add_up_to_the_full_change() -> None:
    rng = np.random.default_rng(1)
    paper = rng.uniform(0.1, 0.5, 30)
    alone = {c: paper + rng.normal(0.02 * i, 0.01, 30) for i, c in enumerate(COMPONENTS)}
    full = paper + 0.2 + rng.normal(0, 0.02, 30)
    full[3] = np.nan  # an eye without a result in one run is left out of every mean
    r = component_changes(paper, alone, full)
    assert r["eyes"] == 29
    assert r["runs"]["paper"]["mean"] + sum(r["change"].values()) + r["interaction"] == pytest.approx(
        r["runs"]["full"]["mean"], abs=1e-14)
    assert r["change"]["tilt"] == pytest.approx(np.mean(np.delete(alone["tilt"] - paper, 3)), abs=1e-14)


def test_each_addition_alone_is_the_full_run_s_draw() -> None:
    eyes = published_eyes()[:6]
    full = full_anatomy(eyes, np.random.default_rng(7))
    alone = component_eyes(eyes, 7)
    np.testing.assert_array_equal(alone["astigmatism"].anterior_radius_perp, full.anterior_radius_perp)
    np.testing.assert_array_equal(alone["astigmatism"].pupil_decentre, eyes.pupil_decentre)
    np.testing.assert_array_equal(alone["decentration"].pupil_decentre, full.pupil_decentre)
    np.testing.assert_array_equal(alone["decentration"].anterior_radius_perp, eyes.anterior_radius_perp)
    np.testing.assert_array_equal(alone["stop"].pupil_eccentricity, full.pupil_eccentricity)
    np.testing.assert_array_equal(alone["tilt"].cornea_tilt_deg, full.cornea_tilt_deg)
    assert np.all(alone["tilt"].pupil_eccentricity == 0)
    params = added_parameters(full)
    assert list(params) == list(GROUPS) and len(params["paper anatomy"]) == 11
    assert np.all(params["astigmatism"]["|J| ant (D)"] > 0) and not np.any(params["astigmatism"]["J0 ant (D)"] == 0)


# -- a small deterministic study run -------------------------------------------------------------------

EYES = 24  # 20 regressors (11 + 6 + 3) need at least 23 eyes


@pytest.fixture(scope="module")
def breakdown_run():
    eyes = published_eyes()[:EYES]
    paper = run_study(eyes, workers=1)
    full, alone = run_anatomy(eyes, 2023, workers=1)
    summary = summarise_study(paper) | {"anatomy": anatomy_summary(paper, full),
                                        "anatomy_breakdown": anatomy_breakdown(paper, alone, full)}
    return eyes, paper, full, alone, summary


def test_the_breakdown_is_consistent_with_the_runs(breakdown_run) -> None:
    _, paper, _, alone, summary = breakdown_run
    b = summary["anatomy_breakdown"]
    assert set(b) == set(summary["anatomy"])
    for col, r in b.items():
        assert r["runs"]["paper"]["mean"] == pytest.approx(summary["anatomy"][col]["paper"]["mean"], abs=1e-12)
        assert r["runs"]["full"]["mean"] == pytest.approx(summary["anatomy"][col]["full"]["mean"], abs=1e-12)
        assert r["runs"]["paper"]["mean"] + sum(r["change"].values()) + r["interaction"] == pytest.approx(
            r["runs"]["full"]["mean"], abs=1e-12)
        v = r["variance"]
        assert v["eyes"] == EYES and sum(v["shares"].values()) == pytest.approx(v["r_squared"], abs=1e-9)
        assert min(v["shares"].values()) > -1e-9 and v["r_squared"] + v["unexplained"] == pytest.approx(1.0)
    h1 = b["H1 best"]
    assert h1["change"]["astigmatism"] == pytest.approx(np.mean(alone["astigmatism"].profiles["best"]["h1"])
                                                        - np.mean(paper.profiles["best"]["h1"]), abs=1e-12)
    # the estimator's spherical cornea cannot represent a toric one: astigmatism moves the best profile most
    # (on the 100 published eyes +0.11 of +0.14 deg, docs/physics.md)
    assert h1["largest_change"] == "astigmatism" and h1["change"]["astigmatism"] > 0.05
    assert h1["change"]["stop"] == pytest.approx(0.0, abs=0.01)


def test_the_breakdown_is_deterministic(breakdown_run) -> None:
    eyes, _, _, alone, _ = breakdown_run
    again = run_study(component_eyes(eyes, 2023)["decentration"][:8], workers=1)
    np.testing.assert_array_equal(again.h1, alone["decentration"].h1[:8])


def test_report_table_json_and_figure(tmp_path, breakdown_run) -> None:
    _, paper, full, _, summary = breakdown_run
    written = write_outputs(paper, summary, tmp_path, full)
    names = {p.name for p in written}
    assert {"fig10_anatomy_breakdown.png", "fig10_anatomy_breakdown.svg"} <= names
    report = (tmp_path / "report.md").read_text()
    assert "## Which added anatomy moves the errors" in report
    row = next(line for line in report.splitlines() if line.startswith("| H1 best | ") and "astigmatism |" in line)
    assert row.endswith("| astigmatism |")
    data = json.loads((tmp_path / "summary.json").read_text())
    assert set(data["anatomy_breakdown"]["C135"]["variance"]["shares"]) == set(GROUPS)
