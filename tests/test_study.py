"""The replication study: outputs of a small run, and the full replication against the published findings."""

from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest

from eyehil.analysis.study.findings import all_findings
from eyehil.analysis.study.replication import run_study
from eyehil.analysis.study.report import write_outputs
from eyehil.analysis.study.summary import summarise_study
from eyehil.emulator.eye.population import sample
from eyehil.emulator.eye.published import published_eyes
from eyehil.parallel import run_chunks


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
            "fig5_sensitivity_guestrin.png", "fig6_blignaut.png", "fig7_sensitivity_blignaut.png",
            "fig8_estimator_profiles.png"} <= names
    data = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert set(data["table4"]) >= {"R_ant_cornea_mm", "Q_ant_cornea", "n_lens"}
    for key in ("H1", "H2"):
        assert {"mean", "sd", "skewness"} <= set(data["guestrin"][key])
        assert {"statistic", "df", "p"} <= set(data["guestrin"]["welch_t"][key])
        assert {"statistic", "df", "p"} <= set(data["guestrin"]["f_test"][key])
    assert set(data["blignaut"]["best_function"]) == {"C5", "C9", "C14", "C18", "C23", "C135"}
    assert set(data["sensitivity"]) == {"H1", "H2", "C5", "C9", "C14", "C18", "C23", "C135"}
    assert data["guestrin"]["profile"] == "study-code" and data["guestrin_compare"]["profile"] == "best"
    assert set(data["sensitivity"]["H1"]["univariate"]) >= {"Q_ant_cornea", "axial_length_mm"}
    assert data["settings"]["head_offsets_mm"]["up 30 mm"] == [0.0, 30.0, 0.0]
    rows = list(csv.DictReader((tmp_path / "out" / "per_eye.csv").open()))
    assert len(rows) == 14 and "H1_deg" in rows[0] and "C135_deg" in rows[0] and "Q_ant_cornea" in rows[0]
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Findings" in report and "![fig4_guestrin.png](fig4_guestrin.png)" in report
    assert "## Remaining departures" in report and "## Estimator profiles: study-code vs best" in report


def test_per_eye_errors_are_finite_and_the_summary_matches_them(small_run) -> None:
    result, summary = small_run
    assert np.isfinite(result.h1).all() and np.isfinite(result.h2).all()
    assert summary["guestrin"]["H1"]["mean"] == pytest.approx(result.h1.mean(), rel=1e-12)
    # underdetermined fits are explicit failures, not numbers: models 3, 4, 7, 8 have > 5 terms at C5
    assert np.isnan(result.blignaut_errors[:, [2, 3, 6, 7], 0]).all()
    assert np.isfinite(result.blignaut_errors[:, :, 1:]).all()


def test_eyes_without_an_error_are_left_out_and_reported(tmp_path, small_run) -> None:
    """A large draw has an eye whose Blignaut fits all fail (10,000 Rozema eyes: the summary stopped with
    'need at least 2 finite values, got 10000'). Such eyes are left out of the means and tests, and counted."""
    result, _ = small_run
    b = result.blignaut_errors.copy()
    b[3] = np.nan
    b[7, :, 0] = np.nan
    h1 = result.h1.copy()
    h1[5] = np.nan
    damaged = replace(result, blignaut_errors=b, h1=h1)
    summary = summarise_study(damaged)
    assert summary["blignaut"]["eyes_without_error"] == {"C5": 2, "C9": 1, "C14": 1, "C18": 1, "C23": 1, "C135": 1}
    assert summary["blignaut"]["one_sample_t"]["C9"]["df"] == 12
    write_outputs(damaged, summary, tmp_path / "out")
    assert "left out of the means and tests: C5 2, C9 1," in (tmp_path / "out" / "report.md").read_text()


def test_parallel_and_serial_runs_agree() -> None:
    eyes = published_eyes()[:4]
    serial = run_study(eyes, workers=1)
    parallel = run_study(eyes, workers=2, chunk_eyes=2)
    np.testing.assert_allclose(parallel.h1, serial.h1, rtol=1e-9)
    np.testing.assert_allclose(parallel.profiles["best"]["h2"], serial.profiles["best"]["h2"], rtol=1e-9)
    np.testing.assert_allclose(parallel.blignaut_errors, serial.blignaut_errors, rtol=1e-9, equal_nan=True)


def test_batched_study_equals_the_per_eye_estimators() -> None:
    """The batched estimators (one LM for all eyes, batched least squares) against the per-eye ones (scipy's
    least_squares / L-BFGS-B per eye, numpy lstsq per fit) on the same published eyes."""
    eyes = published_eyes()[:4]
    batched = run_study(eyes, workers=1)
    per_eye = run_study(eyes, workers=1, batched=False)
    np.testing.assert_allclose(batched.blignaut_errors, per_eye.blignaut_errors, atol=1e-9, equal_nan=True)
    for key in ("h1", "h2"):  # least squares: the same minimum, to 1e-6 deg
        np.testing.assert_allclose(batched.profiles["best"][key], per_eye.profiles["best"][key], atol=1e-6)
    for key in ("h1", "h2"):  # the sum of errors is flat along R-K; L-BFGS-B stops within 2e-4 deg of it
        np.testing.assert_allclose(batched.profiles["study-code"][key], per_eye.profiles["study-code"][key],
                                   atol=2e-4)


def test_head_position_sets() -> None:
    eyes = published_eyes()[:3]
    text = run_study(eyes, workers=1, compare=None, head_positions="paper-text")
    assert text.settings["head_offsets_mm"]["forward 40 mm"] == [0.0, 0.0, 40.0]
    assert set(text.profiles) == {"study-code"}
    with pytest.raises(ValueError):
        run_study(eyes, head_positions="sideways")


def test_dask_scheduler_runs_the_same_work() -> None:
    distributed = pytest.importorskip("distributed", reason="the optional 'dask' extra is not installed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl:
        out = run_chunks(pow, [2, 3], sizes=[1, 1], scheduler=cl.scheduler_address, exp=2)
    assert out == [4, 9]


def _malloc_tuned(_chunk) -> bool:
    from eyehil import parallel

    return parallel._malloc_tuned


def test_every_chunk_runs_after_the_malloc_thresholds_are_fixed(monkeypatch) -> None:
    """Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which made the forward model 3x slower in
    them (docs/benchmarks.md); chunks run after `tune_malloc` in this process, on the local pool and on Dask."""
    import platform

    from eyehil import parallel

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("malloc thresholds are glibc's; this C library is not glibc")
    assert parallel.tune_malloc()
    monkeypatch.setattr(parallel, "_malloc_tuned", False)
    assert run_chunks(_malloc_tuned, [0], sizes=[1], workers=1) == [True]
    monkeypatch.setattr(parallel, "_malloc_tuned", False)  # the pool's forked workers start untuned
    assert run_chunks(_malloc_tuned, [0, 1], sizes=[1, 1], workers=2) == [True, True]
    distributed = pytest.importorskip("distributed", reason="the optional 'dask' extra is not installed")
    monkeypatch.setattr(parallel, "_malloc_tuned", False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl:
        assert run_chunks(_malloc_tuned, [0, 1], sizes=[1, 1], scheduler=cl.scheduler_address) == [True, True]


def _findings(eyes, key: str | None = None):
    result = run_study(eyes)
    if key:
        _CACHE[f"{key}_result"] = result
    return {f.claim: f for f in all_findings(summarise_study(result))}


_CACHE: dict[str, dict] = {}


def _published_findings(request) -> dict:
    if "published" not in _CACHE:
        _CACHE["published"] = _findings(published_eyes(), "published")
    return _CACHE["published"]


def _fresh_findings(request) -> dict:
    if "fresh" not in _CACHE:
        _CACHE["fresh"] = _findings(sample(100, np.random.default_rng(2023)).eyes)
    return _CACHE["fresh"]


@pytest.fixture(params=["published", "fresh draw"])
def replication(request):
    return _published_findings(request) if request.param == "published" else _fresh_findings(request)


STRUCTURE = [
    "Guestrin H1: right-skewed, skewness > 1.5 (published 1.86)",
    "Guestrin H2: right-skewed, skewness > 1.5 (published 1.84)",
    "H1: Q_ac the dominant parameter (>= 5x any other significant one; our check)",
    "H2: Q_ac the dominant parameter (>= 5x any other significant one; our check)",
    "H1: R^2 >= 0.95 (published .99)", "H2: R^2 >= 0.95 (published .99)",
    "Blignaut: best-function error falls 0.1-0.3 deg from C5 to C9 (published 0.20, real 0.28)",
    "Blignaut: changes below 0.1 deg beyond C14",
    "Blignaut: Q_ac the strongest parameter at every configuration",
]
LEVEL = [
    "Guestrin H1: mean 0.33-0.39 deg (published 0.36)", "Guestrin H2: mean 0.33-0.39 deg (published 0.36)",
    "Guestrin H1: SD 0.17-0.23 deg (published 0.20)", "Guestrin H2: SD 0.17-0.23 deg (published 0.20)",
    "H1: |Q_ac coefficient| 0.18-0.22 deg/SD (published 0.2)",
    "H2: |Q_ac coefficient| 0.18-0.22 deg/SD (published 0.2)",
]


@pytest.mark.parametrize("claim", STRUCTURE)
def test_replication_reproduces_the_published_structure(replication, claim: str) -> None:
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"


ONLY = ["H1: Q_ac the only significant parameter (multivariate, p < .05)",
        "H2: Q_ac the only significant parameter (multivariate, p < .05)"]


@pytest.mark.parametrize("claim", ONLY)
def test_q_ac_is_the_only_significant_parameter(request, replication, claim: str) -> None:
    if request.node.callspec.params["replication"] == "fresh draw":
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            "known departure on the fresh Rozema draw (seed 2023): R_ac, R_pc, axial length and Q_pc (and ACD for "
            "H2) also reach p < .05 with coefficients 8-30x smaller than Q_ac's (-0.218 vs -0.026 ... -0.007 "
            "deg/SD); on the published eyes Q_ac is the only one, as published")))
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"


@pytest.mark.parametrize("claim", LEVEL)
def test_replication_reproduces_the_published_guestrin_level(replication, claim: str) -> None:
    f = replication[claim]
    assert f.holds, f"{claim}: replicated {f.replicated}"


def test_the_best_profile_is_below_the_published_level() -> None:
    """The finding beyond the paper: eyehil's own estimator on the same features (published eyes)."""
    s = summarise_study(_CACHE.get("published_result") or run_study(published_eyes()))
    c = s["guestrin_compare"]
    assert c["profile"] == "best"
    assert 0.18 <= c["H1"]["mean"] <= 0.24 and 0.08 <= c["H1"]["sd"] <= 0.12
    assert c["H1"]["mean"] < 0.7 * s["guestrin"]["H1"]["mean"]
    assert 0.08 <= abs(c["sensitivity"]["H1"]["coefficients"]["Q_ant_cornea"]["coef"]) <= 0.12
