"""The Rozema 2011 population: sampling, conversion, thick-lens index, rejections (eye-model.md section 1).

Tolerances come from sampling error, never from the result. The reference figures for 200,000 draws are
themselves one 200,000-draw sample, so the difference of two independent samples has standard error
sqrt(2) SE; a mean or SD must agree within 5 sqrt(2) SE plus half the last digit the reference is rounded to.
SE of a mean = s / sqrt(n); SE of an SD = s sqrt((kurtosis - 1) / (4 n)) (valid for non-normal Q_ac too).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from eyehil.emulator.eye.population import (
    REJECTION_REASONS,
    STUDY_KEYS,
    TABLE4_KEYS,
    parameter_table,
    rejection_codes,
    sample,
    sample_raw,
    study_parameters,
)
from eyehil.emulator.eye.rozema import RawDraws, rozema2011, thick_lens_index

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
N_LARGE = 200_000


@pytest.fixture(scope="module")
def large():
    return sample(N_LARGE, np.random.default_rng(2011))


def _se_mean_sd(x: np.ndarray) -> tuple[float, float]:
    s = x.std(ddof=1)
    kurtosis = np.mean((x - x.mean()) ** 4) / np.var(x) ** 2
    return s / np.sqrt(x.size), s * np.sqrt((kurtosis - 1.0) / (4.0 * x.size))


@pytest.mark.parametrize(
    ("quantity", "mean", "sd", "rounding"),
    [("R_ac", 7.795, 0.245, 0.0005), ("Q_ac", -0.193, 0.147, 0.0005), ("K", 4.38, 0.47, 0.005),
     ("stop_depth", 3.416, 0.390, 0.0005)],
)
def test_large_draw_reproduces_reference(large, quantity, mean, sd, rounding):
    e = large.eyes
    values = {"R_ac": e.anterior_radius, "Q_ac": e.anterior_conic, "K": e.anterior_radius - e.stop_depth,
              "stop_depth": e.stop_depth}[quantity]
    se_mean, se_sd = _se_mean_sd(values)
    assert abs(values.mean() - mean) < 5 * np.sqrt(2) * se_mean + rounding
    assert abs(values.std(ddof=1) - sd) < 5 * np.sqrt(2) * se_sd + rounding


def test_raw_draws_follow_the_published_normal():
    raw = sample_raw(N_LARGE, np.random.default_rng(7))
    model = rozema2011()
    se = model.sd / np.sqrt(N_LARGE)
    assert np.all(np.abs(raw.values.mean(axis=0) - model.mean) < 5 * se)
    corr = np.corrcoef(raw.values, rowvar=False)
    i, j = model.index("K_ant_M"), model.index("K_post_M")
    published = model.covariance[i, j] / np.sqrt(model.covariance[i, i] * model.covariance[j, j])
    assert corr[i, j] == pytest.approx(published, abs=5 * (1 - published**2) / np.sqrt(N_LARGE))
    assert published == pytest.approx(-0.90, abs=0.005)


def test_embedded_data_match_the_shared_tables():
    model = rozema2011()
    rows = list(csv.DictReader((SHARED / "rozema2011_mean.csv").read_text().splitlines()))
    assert model.names == tuple(r["name"] for r in rows)
    assert np.array_equal(model.mean, [float(r["mean"]) for r in rows])
    assert np.array_equal(model.sd, [float(r["sd"]) for r in rows])
    shared = np.genfromtxt(SHARED / "rozema2011_cov.csv", delimiter=",", skip_header=1)[:, 1:]
    assert np.array_equal(model.covariance, shared)
    assert "10.1167/iovs.10-6705" in model.citation


def test_thick_lens_index_at_the_mean():
    m = rozema2011().mean_draw()
    n = thick_lens_index(m["lens_power"], m["R_lens_ant"], m["R_lens_post"], m["lens_thickness"])
    assert n[0] == pytest.approx(1.433, abs=0.001)
    eye = sample(1, np.random.default_rng(0), lens_index="thick-lens").eyes
    assert 1.38 < eye.lens_index[0] < 1.5


def test_thick_lens_index_inverts_the_thick_lens_power():
    rng = np.random.default_rng(3)
    r1, r2, t = rng.uniform(7, 14, 1000), -rng.uniform(4.5, 9, 1000), rng.uniform(2.5, 5.5, 1000)
    n_true = rng.uniform(1.38, 1.5, 1000)
    f1, f2 = (n_true - 1.336) / (r1 * 1e-3), (1.336 - n_true) / (r2 * 1e-3)
    power = f1 + f2 - (t * 1e-3 / n_true) * f1 * f2
    assert np.allclose(thick_lens_index(power, r1, r2, t), n_true, rtol=0, atol=1e-12)


def test_fixed_lens_index():
    eyes = sample(20, np.random.default_rng(1), lens_index=1.42).eyes
    assert np.all(eyes.lens_index == 1.42)


def test_rejection_codes_of_a_tiny_hand_made_example():
    model = rozema2011()
    values = np.repeat(model.mean[None, :], 7, axis=0)
    bad = [("ecc_ant", 1.2), ("ecc_post", -1.05), ("ACD", -0.1), ("pupil_diameter_scotopic", 12.5),
           ("axial_length", 7.0), ("lens_power", 200.0)]
    for row, (name, value) in enumerate(bad, start=1):
        values[row, model.index(name)] = value
    codes = rejection_codes(RawDraws(values, model.names))
    assert codes.tolist() == [0, 1, 2, 3, 4, 5, 6]
    assert rejection_codes(RawDraws(values, model.names), 1.42)[6] == 0  # a fixed index cannot fail


def test_rejections_counted_when_forced():
    model = rozema2011().with_mean(ecc_post=0.9)  # about 36 % of draws have |e_post| >= 1
    n = 2000
    draw = sample(n, np.random.default_rng(5), model=model)
    assert len(draw.eyes) == n
    assert set(draw.rejections) == set(REJECTION_REASONS)
    assert draw.attempts == n + draw.n_rejected
    assert np.all(draw.eyes.posterior_conic > -1)
    sd_e = model.sd[model.index("ecc_post")]
    p_reject = norm.sf(1, 0.9, sd_e) + norm.cdf(-1, 0.9, sd_e)
    expected = n * p_reject / (1 - p_reject)  # negative binomial: failures before n successes
    sd = np.sqrt(n * p_reject) / (1 - p_reject)
    assert abs(draw.rejections["posterior_cornea_not_ellipsoid"] - expected) < 5 * sd
    assert "posterior_cornea_not_ellipsoid" in draw.summary()


def test_rejection_rate_of_the_population_is_plausible(large):
    model = rozema2011()
    for reason, name in [("anterior_cornea_not_ellipsoid", "ecc_ant"), ("posterior_cornea_not_ellipsoid", "ecc_post")]:
        mu, sd = model.mean[model.index(name)], model.sd[model.index(name)]
        p = norm.sf(1, mu, sd) + norm.cdf(-1, mu, sd)
        expected = large.attempts * p
        assert abs(large.rejections[reason] - expected) < 5 * np.sqrt(expected)
    assert large.rejection_rate < 0.005
    assert np.all(np.abs(large.eyes.anterior_conic) < 1) and np.all(np.abs(large.eyes.posterior_conic) < 1)


def test_same_seed_same_eyes_and_left_mirrors_right():
    right = sample(50, np.random.default_rng(42)).eyes
    again = sample(50, np.random.default_rng(42)).eyes
    left = sample(50, np.random.default_rng(42), laterality="left").eyes
    other = sample(50, np.random.default_rng(43)).eyes
    assert np.array_equal(right.anterior_radius, again.anterior_radius)
    assert not np.array_equal(right.anterior_radius, other.anterior_radius)
    assert np.array_equal(right.axial_length, left.axial_length)
    assert np.all(right.side_sign == 1) and np.all(left.side_sign == -1)
    assert np.array_equal(right.alpha_h, left.alpha_h)  # stored nasal-positive for both eyes
    r_centre, l_centre = right.frame_vector(right.azimuth_centre), left.frame_vector(left.azimuth_centre)
    assert np.allclose(r_centre[:, 0], -l_centre[:, 0]) and np.all(r_centre[:, 0] > 0)


@pytest.mark.parametrize("n", [0, -3, 2.5, True])
def test_bad_n(n):
    with pytest.raises(ValueError, match="positive integer"):
        sample(n, np.random.default_rng(0))


@pytest.mark.parametrize("lens_index", ["thin-lens", "1.42", 0.9, float("nan")])
def test_bad_lens_index(lens_index):
    with pytest.raises(ValueError, match="lens_index"):
        sample(3, np.random.default_rng(0), lens_index=lens_index)


def test_bad_laterality():
    with pytest.raises(ValueError, match="laterality"):
        sample(3, np.random.default_rng(0), laterality="up")


def test_parameter_table_and_study_parameters(large):
    table = parameter_table(large.eyes[:1000])
    assert tuple(table) == TABLE4_KEYS
    params = study_parameters(large.eyes[:1000])
    assert tuple(params) == STUDY_KEYS and all(v.shape == (1000,) for v in params.values())
    stop = params["CCT_mm"] + params["ACD_mm"]
    assert table["ACD_from_anterior_cornea_mm"][0] == pytest.approx(stop.mean())
    assert table["pupil_diameter_mm"][1] == pytest.approx(np.std(params["pupil_diameter_mm"], ddof=1))
    with pytest.raises(ValueError, match="two eyes"):
        parameter_table(large.eyes[:1])
