"""The replication study: outputs of a small run, and the full replication against the published findings."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from eyehil.analysis.study.findings import all_findings
from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.report import write_outputs
from eyehil.analysis.study.runner import run_chunks
from eyehil.analysis.study.summary import summarise_study
from eyehil.emulator.eye.population import sample
from eyehil.emulator.eye.published import published_eyes


@pytest.fixture(scope="module")
def small_run():
    eyes = published_eyes()[:14]
    result = run_study(eyes, workers=1)
    return result, summarise_study(result)


def test_small_run_writes_every_output(tmp_path, small_run) -> None:
    result, summary = small_run
    written = write_outputs(result, summary, tmp_path / "out")
    names = {p.name for p in written}
    assert {"summary.json", "per_eye.csv", "report.md", "fig3_features.png", "fig4_guestrin.png",
            "fig5_sensitivity_guestrin.png", "fig6_blignaut.png", "fig7_sensitivity_blignaut.png"} <= names
    data = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert set(data["table4"]) >= {"R_ant_cornea_mm", "Q_ant_cornea", "n_lens"}
    for key in ("H1", "H2"):
        assert {"mean", "sd", "skewness"} <= set(data["guestrin"][key])
        assert {"statistic", "df", "p"} <= set(data["guestrin"]["welch_t"][key])
        assert {"statistic", "df", "p"} <= set(data["guestrin"]["f_test"][key])
    assert set(data["blignaut"]["best_function"]) == {"C5", "C9", "C14", "C18", "C23", "C135"}
    assert set(data["sensitivity"]) == {"H1", "H2", "C5", "C9", "C14", "C18", "C23", "C135"}
    rows = list(csv.DictReader((tmp_path / "out" / "per_eye.csv").open()))
    assert len(rows) == 14 and "H1_deg" in rows[0] and "C135_deg" in rows[0] and "Q_ant_cornea" in rows[0]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Findings" in report and "![fig4_guestrin.png](fig4_guestrin.png)" in report


def test_per_eye_errors_are_finite_and_the_summary_matches_them(small_run) -> None:
    result, summary = small_run
    assert np.isfinite(result.h1).all() and np.isfinite(result.h2).all()
    assert summary["guestrin"]["H1"]["mean"] == pytest.approx(result.h1.mean(), rel=1e-12)
    # underdetermined fits are explicit failures, not numbers: models 3, 4, 7, 8 have > 5 terms at C5
    assert np.isnan(result.blignaut_errors[:, [2, 3, 6, 7], 0]).all()
    assert np.isfinite(result.blignaut_errors[:, :, 1:]).all()


def test_parallel_and_serial_runs_agree() -> None:
    eyes = published_eyes()[:4]
    serial = run_study(eyes, workers=1)
    parallel = run_study(eyes, workers=2)
    np.testing.assert_allclose(parallel.h1, serial.h1, rtol=1e-9)
    np.testing.assert_allclose(parallel.blignaut_errors, serial.blignaut_errors, rtol=1e-9, equal_nan=True)


def test_dask_scheduler_runs_the_same_work() -> None:
    distributed = pytest.importorskip("distributed", reason="the optional 'dask' extra is not installed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl:
        out = run_chunks(pow, [2, 3], sizes=[1, 1], scheduler=cl.scheduler_address, exp=2)
    assert out == [4, 9]


def _findings(eyes):
    return {f.claim: f for f in all_findings(summarise_study(run_study(eyes)))}


_CACHE: dict[str, dict] = {}


def _published_findings(request) -> dict:
    if "published" not in _CACHE:
        _CACHE["published"] = _findings(published_eyes())
    return _CACHE["published"]


def _fresh_findings(request) -> dict:
    if "fresh" not in _CACHE:
        _CACHE["fresh"] = _findings(sample(100, np.random.default_rng(2023)).eyes)
    return _CACHE["fresh"]


@pytest.fixture(params=["published", "fresh draw"])
def replication(request):
    return _published_findings(request) if request.param == "published" else _fresh_findings(request)


STRUCTURE = [
    "Guestrin H1: right-skewed (published 1.86)", "Guestrin H2: right-skewed (published 1.84)",
    "H1: Q_ac the dominant parameter (>= 5x any other significant one; our check)",
    "H2: Q_ac the dominant parameter (>= 5x any other significant one; our check)",
    "H1: R^2 >= 0.9 (published .99)", "H2: R^2 >= 0.9 (published .99)",
    "Blignaut: best-function error falls 0.1-0.3 deg from C5 to C9 (published 0.20, real 0.28)",
    "Blignaut: changes below 0.1 deg beyond C14",
    "Blignaut: Q_ac the strongest parameter at every configuration",
]
LEVEL = [
    "Guestrin H1: mean 0.30-0.42 deg (published 0.36)", "Guestrin H2: mean 0.30-0.42 deg (published 0.36)",
    "H1: |Q_ac coefficient| 0.15-0.25 deg/SD (published 0.2)",
]


@pytest.mark.parametrize("claim", STRUCTURE)
def test_replication_reproduces_the_published_structure(replication, claim: str) -> None:
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"


ONLY = ["H1: Q_ac the only significant parameter", "H2: Q_ac the only significant parameter"]


@pytest.mark.xfail(strict=True, reason="known departure: lens thickness and axial length also reach p < .05 for "
                   "H1/H2 with effects about 15x smaller than Q_ac's (published eyes: +0.007 and -0.007 vs -0.102 "
                   "deg/SD; fresh draw: AL and Q_pc); the dominance test above holds")
@pytest.mark.parametrize("claim", ONLY)
def test_q_ac_is_the_only_significant_parameter(replication, claim: str) -> None:
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"


@pytest.mark.xfail(strict=True, reason="known departure: replicated Guestrin errors are about 0.21 deg, published "
                   "0.36 (see report.md findings note [1] and the issue note)")
@pytest.mark.parametrize("claim", LEVEL)
def test_replication_reproduces_the_published_guestrin_level(replication, claim: str) -> None:
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"
