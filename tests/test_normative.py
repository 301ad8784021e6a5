"""Published eyes (Fischer et al. 2023) and named normative eyes (eye-model.md sections 1 and 4).

Table 4 of the paper and the shared eye file are two different 100-eye samples (no parameter agrees to the
rounding shown); the file is checked exactly against the shared copy, against Table 4 within the sampling error
of two independent 100-eye samples (5 sqrt(2) SE plus rounding), and the rounding-level agreement is recorded
as a strict expected failure.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from eyehil.emulator.eye.normative import NORMATIVE_NAMES, normative_eye, normative_media
from eyehil.emulator.eye.population import parameter_table
from eyehil.emulator.eye.published import HYPERBOLOID_CLIP, conditional_lens_power, published_biometry, published_eyes
from eyehil.emulator.eye.rozema import rozema2011

SHARED_EYES = Path(__file__).resolve().parents[2] / "shared" / "data" / "fischer2023_eyes.csv"
#: Table 4 of Fischer et al. 2023: mean, SD, and half the last digit shown (n_lens left out: see below).
TABLE4 = {
    "R_ant_cornea_mm": (7.79, 0.24, 0.005), "Q_ant_cornea": (-0.21, 0.16, 0.005),
    "R_post_cornea_mm": (6.52, 0.24, 0.005), "Q_post_cornea": (-0.11, 0.17, 0.005),
    "CCT_mm": (0.545, 0.037, 0.0005), "ACD_from_anterior_cornea_mm": (3.41, 0.37, 0.005),
    "pupil_diameter_mm": (6.44, 1.20, 0.005), "R_lens_ant_mm": (10.47, 1.32, 0.005),
    "R_lens_post_mm": (6.96, 0.89, 0.005), "lens_thickness_mm": (4.00, 0.51, 0.005),
    "axial_length_mm": (23.74, 1.07, 0.005),
}


def test_published_eyes_load():
    eyes = published_eyes()
    assert len(eyes) == 100
    assert np.all(eyes.lens_index == 1.42) and not eyes.left.any()
    assert published_eyes(lens_index=1.40).lens_index[0] == 1.40


def test_published_statistics_equal_the_shared_file():
    shared = np.genfromtxt(SHARED_EYES, delimiter=",", names=True)
    table = parameter_table(published_eyes())
    for key, (mean, sd) in table.items():
        if key == "n_lens":
            continue
        column = shared["CCT_mm"] + shared["ACD_mm"] if key == "ACD_from_anterior_cornea_mm" else shared[key]
        if key == "Q_post_cornea":
            column = np.maximum(column, HYPERBOLOID_CLIP)  # eye 75: -1.163 clipped to -0.999
        assert mean == pytest.approx(column.mean(), abs=1e-12)
        assert sd == pytest.approx(column.std(ddof=1), abs=1e-12)


def test_published_eyes_agree_with_table4_within_sampling_error():
    table = parameter_table(published_eyes())
    for key, (mean, sd, rounding) in TABLE4.items():
        se_mean, se_sd = sd / np.sqrt(100), sd / np.sqrt(2 * 99)
        assert abs(table[key][0] - mean) < 5 * np.sqrt(2) * se_mean + rounding, key
        assert abs(table[key][1] - sd) < 5 * np.sqrt(2) * se_sd + rounding, key


@pytest.mark.xfail(strict=True, reason="the shared eye file is not the sample behind Table 4 (e.g. AL 23.62 vs 23.74)")
def test_published_eyes_reproduce_table4_to_the_rounding_shown():
    table = parameter_table(published_eyes())
    for key, (mean, sd, rounding) in TABLE4.items():
        assert abs(table[key][0] - mean) <= rounding and abs(table[key][1] - sd) <= rounding, key


def test_hyperboloid_handling():
    raw = published_biometry()
    assert raw["Q_post_cornea"][74] == pytest.approx(-1.1627, abs=1e-4) and raw["eye"][74] == 75
    assert published_eyes().posterior_conic[74] == HYPERBOLOID_CLIP
    assert len(published_eyes(hyperboloids="drop")) == 99
    with pytest.raises(ValueError, match=r"\[75\]"):
        published_eyes(hyperboloids="raise")
    with pytest.raises(ValueError, match="hyperboloids"):
        published_eyes(hyperboloids="keep")


def test_published_thick_lens_estimate():
    mean = rozema2011().mean
    biometry = {k: np.atleast_1d(v) for k, v in {
        "R_ant_cornea_mm": 337.2 / mean[1], "R_post_cornea_mm": -40.8 / mean[5], "R_lens_ant_mm": mean[9],
        "R_lens_post_mm": -mean[10], "lens_thickness_mm": mean[11], "CCT_mm": mean[12], "ACD_mm": mean[13],
        "axial_length_mm": mean[14], "pupil_diameter_mm": mean[15]}.items()}
    assert conditional_lens_power(biometry)[0] == pytest.approx(mean[16], abs=1e-9)
    n = published_eyes(lens_index="thick-lens").lens_index
    assert np.all((n > 1.38) & (n < 1.5)) and abs(n.mean() - 1.433) < 0.005


@pytest.mark.parametrize("lens_index", ["fixed", -1.0])
def test_published_bad_lens_index(lens_index):
    with pytest.raises(ValueError, match="lens_index"):
        published_eyes(lens_index=lens_index)


def test_published_left_eyes_mirror_right():
    right, left = published_eyes(), published_eyes("left")
    assert np.all(left.side_sign == -1) and np.array_equal(left.alpha_h, right.alpha_h)
    assert np.allclose(left.frame_vector(left.azimuth_centre)[:, 0], -right.frame_vector(right.azimuth_centre)[:, 0])


@pytest.mark.parametrize(
    ("name", "values"),
    [("navarro", (7.72, -0.26, 6.50, 0.0, 0.55, 3.05, 23.9203, 1.42)),
     ("atchison", (7.77, -0.15, 6.40, -0.275, 0.55, 3.15, 23.58, 1.4319)),
     ("et_simul", (7.98, 0.0, 6.22, 0.0, 1.15, 2.39, 23.58, 1.376))],
)
def test_normative_values(name, values):
    e = normative_eye(name)
    got = (e.anterior_radius, e.anterior_conic, e.posterior_radius, e.posterior_conic, e.cct, e.acd,
           e.axial_length, e.lens_index)
    assert np.allclose(got, values, rtol=0, atol=1e-12)
    assert e.shape == ()


def _refraction(e, media) -> float:
    """Paraxial refraction (D, + hyperopic) at the corneal apex: the vergence of the light that focuses on the
    retina (y-nu trace; an axial object at distance d gives nu = 1/d = -vergence)."""
    surfaces = [(e.anterior_radius, 1.0, media.cornea, e.cct), (e.posterior_radius, media.cornea, media.aqueous, e.acd),
                (e.lens_anterior_radius, media.aqueous, e.lens_index, e.lens_thickness),
                (-e.lens_posterior_radius, e.lens_index, media.vitreous, e.vitreous_length)]

    def height_at_retina(vergence_per_mm: float) -> float:
        y, nu = 1.0, vergence_per_mm
        for radius, n1, n2, gap in surfaces:
            nu -= y * (n2 - n1) / radius
            y += gap * nu / n2
        return y

    return -1000.0 * brentq(height_at_retina, -0.05, 0.05)


def test_navarro_and_atchison_are_emmetropic():
    # Navarro's indices are those at 589 nm; the eye's chromatic difference of refraction from the design
    # wavelength (543 nm) is about +0.2 D, and the model computes +0.23 D.
    assert 0.0 < _refraction(normative_eye("navarro"), normative_media("navarro")) < 0.3
    assert abs(_refraction(normative_eye("atchison"), normative_media("atchison"))) < 0.02


def test_et_simul():
    e, media = normative_eye("et_simul"), normative_media("et_simul")
    assert (float(e.alpha_h), float(e.alpha_v)) == (6.0, 2.0)
    assert float(e.stop_depth) == pytest.approx(3.54) and float(e.pupil_radius) == 3.0
    assert np.allclose(e.azimuth_centre, [0, 0, -12.33]) and np.allclose(e.elevation_centre, [0, 0, -12.33])
    assert media.cornea == media.aqueous == media.vitreous == float(e.lens_index) == 1.376


def test_mean_eye():
    e = normative_eye("mean")
    assert float(e.anterior_radius) == pytest.approx(337.2 / 43.294)
    assert float(e.posterior_radius) == pytest.approx(6.512, abs=5e-4)
    assert float(e.lens_index) == pytest.approx(1.433, abs=0.001)
    assert float(e.vitreous_length) == pytest.approx(16.182) and float(e.alpha_h) == pytest.approx(5.45)
    assert normative_media("mean").label == "study-code"


@pytest.mark.parametrize("name", NORMATIVE_NAMES)
def test_normative_left_mirrors_right_and_pupil_override(name):
    right, left = normative_eye(name), normative_eye(name, "left", pupil_diameter=5.0)
    assert float(right.side_sign) == 1 and float(left.side_sign) == -1 and left.alpha_h == right.alpha_h
    assert left.frame_vector(left.azimuth_centre)[0] == -right.frame_vector(right.azimuth_centre)[0]
    assert float(left.pupil_radius) == 2.5


def test_unknown_normative_name():
    with pytest.raises(ValueError, match="navarro, atchison, et_simul, mean"):
        normative_eye("gullstrand")
    with pytest.raises(ValueError, match="known"):
        normative_media("gullstrand")
