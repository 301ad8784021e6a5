"""Synthetic IR frames: outline geometry known answers, drawing, noise, windows, determinism, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.forward import Poses, simulate
from eyehil.emulator.render import kernels
from eyehil.emulator.render.draw import _sub, periodic_lerp
from eyehil.emulator.render.geometry import _upsampler, clip_unit, eye_outlines, pupil_polar
from eyehil.emulator.render.noise import CounterNoise
from eyehil.emulator.render.renderer import (
    Appearance,
    RenderSettings,
    Sensor,
    expose,
    render_features,
    render_full,
    render_roi,
    roi_window,
    uniform16,
)
from eyehil.emulator.scene import load_scene


@pytest.fixture(scope="module")
def guestrin():
    scene = load_scene("guestrin2006")
    eyes = published_eyes()[:3]
    features = simulate(eyes, scene, head_positions=scene.head_positions[:1])
    return scene, eyes, features, eye_outlines(features, eyes, scene)


def test_fourier_outline_reproduces_an_ellipse_exactly():
    t = 2 * np.pi * np.arange(30) / 30
    a, b, phi, c = 20.0, 14.0, np.radians(30.0), np.array([100.3, 50.7])
    z = (a * np.cos(t) + 1j * b * np.sin(t)) * np.exp(1j * phi)
    points = np.stack([z.real, z.imag], -1) + c
    theta, r, _ = pupil_polar(points, np.ones(30, bool), c, np.array([2 * a, 2 * b]), np.degrees(phi))
    u, v = np.cos(theta - phi), np.sin(theta - phi)
    np.testing.assert_allclose(r, 1.0 / np.sqrt((u / a) ** 2 + (v / b) ** 2), rtol=1e-9)
    assert np.all(np.diff(theta) > 0)


@pytest.mark.parametrize("n", [29, 30])
def test_outline_interpolation_matrix_is_the_fft_interpolant(n):
    """`pupil_polar`'s real matrix equals zero-padded FFT interpolation (Nyquist term split for even n) and
    passes through the samples."""
    z = np.random.default_rng(n).normal(size=n) + 1j * np.random.default_rng(n + 1).normal(size=n)
    m = 4 * n
    spec = np.fft.fft(z)
    padded = np.zeros(m, complex)
    h = (n + 1) // 2
    padded[:h], padded[m - (n - h):] = spec[:h], spec[h:]
    if n % 2 == 0:
        padded[n // 2] = padded[m - n // 2] = spec[n // 2] / 2
    expected = np.fft.ifft(padded) * (m / n)
    matrix = _upsampler(n, m)
    np.testing.assert_allclose(z.real @ matrix + 1j * (z.imag @ matrix), expected, atol=1e-12)
    np.testing.assert_allclose(z.real @ matrix[:, ::4], z.real, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 40), st.integers(0, 2**32 - 1))
def test_periodic_lerp_is_numpy_periodic_interp(m, seed) -> None:
    """One search for both tables, around the circle: `np.interp(..., period=2 pi)` to rounding, at any angle,
    at the table's own angles and at the seam (+-pi)."""
    rng = np.random.default_rng(seed)
    theta = np.sort(rng.uniform(-np.pi, np.pi, m))
    table = rng.normal(size=(2, m))
    phi = np.concatenate([rng.uniform(-np.pi, np.pi, 200), theta, [-np.pi, np.pi]]).astype(np.float32)
    got = periodic_lerp(phi, theta, table)
    for k in range(2):
        np.testing.assert_allclose(got[k], np.interp(phi, theta, table[k], period=2 * np.pi), rtol=1e-12, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.integers(-50, 400), st.integers(1, 60), st.floats(-100, 500), st.floats(0, 80))
def test_sub_slices_are_the_pixels_within_reach(first, n, centre, half) -> None:
    """`_sub`'s slices hold exactly the pixels of consecutive coordinates within `half` of the centre (the
    definition it replaced: `np.nonzero(abs(x - centre) <= half)`), in both directions; None when there are none
    or the centre is not finite."""
    x = np.arange(first, first + n, dtype=np.float32)
    y = x[:, None]
    got = _sub(x, y, np.array([centre, centre]), half)
    want = np.nonzero(np.abs(x - centre) <= half)[0]
    if not len(want):
        assert got is None
    else:
        assert got is not None
        assert list(range(n))[got[1]] == list(want) == list(range(n))[got[0]]
    assert _sub(x, y, np.array([np.nan, centre]), half) is None


def test_clip_unit_is_np_clip_in_place() -> None:
    values = np.array([-np.inf, -1.0, 0.0, 0.25, 1.0, 3.0, np.inf, np.nan], np.float32)
    want = np.clip(values, 0.0, 1.0)
    got = clip_unit(values)
    assert got is values
    np.testing.assert_array_equal(got, want)


def test_limbus_is_the_projected_corneal_edge(guestrin):
    scene, eyes, features, outline = guestrin
    cam = scene.camera
    depth = cam.to_camera(features.apex)[..., 2]
    expected = 2 * eyes.limbus_radius[:, None, None, None] * cam.focal_px[0] / depth
    np.testing.assert_allclose(outline.limbus_axes_px[..., 0], expected, rtol=0.03)
    offset = np.linalg.norm(outline.limbus_centre_px - features.pupil_centre_px, axis=-1)
    assert np.all(offset < 0.25 * outline.limbus_axes_px[..., 0])  # the pupil sits inside the iris


def test_blink_closes_the_lids_and_hides_the_pupil(guestrin):
    scene, eyes, features, _ = guestrin
    closed = eye_outlines(features, eyes, scene, blink=1.0)
    np.testing.assert_allclose(closed.upper_lid_px, closed.lower_lid_px, atol=1e-9)
    frame = render_roi(closed[0, 0, 0, 4], np.random.default_rng(0))
    assert frame.truth.pupil_visible[0] == 0.0 and not frame.truth.glint_visible.any()
    assert frame.image.min() > 150  # only skin: no pupil, iris or glint
    half = eye_outlines(features, eyes, scene, blink=0.5)[0, 0, 0, 4]
    assert 0.0 < render_roi(half, np.random.default_rng(0)).truth.pupil_visible[0] < 1.0


def test_lids_follow_gaze_elevation():
    scene = load_scene("guestrin2006")
    eye = normative_eye("navarro").as_batch()
    features = simulate(eye, scene, poses=Poses(np.zeros(2), np.array([15.0, -15.0])),
                        head_positions=scene.head_positions[:1])
    outline = eye_outlines(features, eye, scene)
    mid = outline.upper_lid_px.shape[-2] // 2
    up, down = outline.upper_lid_px[0, 0, 0, :, mid, 1]
    assert up < down - 10  # looking up raises the upper lid (image y decreases) by more than 10 px
    assert np.all(outline.upper_lid_px[..., 1] <= outline.lower_lid_px[..., 1] + 1e-9)


def test_frames_are_deterministic_given_the_generator(guestrin):
    *_, outline = guestrin
    sample = outline[1, 0, 0, 2]
    a = render_roi(sample, np.random.default_rng(7)).image
    b = render_roi(sample, np.random.default_rng(7)).image
    c = render_roi(sample, np.random.default_rng(8)).image
    assert a.dtype == np.uint8 and a.shape == (240, 320)
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)


NO_KERNEL = pytest.mark.skipif(not kernels.AVAILABLE, reason=f"compiled kernel unavailable: {kernels.REASON}")
#: expose's flat-canvas path: the compiled kernel where it is built, and the numpy path.
FLAT_PATHS = [pytest.param(True, marks=NO_KERNEL, id="compiled"), pytest.param(False, id="numpy")]
NOISES = ["generator", "counter"]  # a numpy generator's draws, or a counter noise's (computed in the kernel's pass)


def _noise(kind: str, seed: int):
    return np.random.default_rng(seed) if kind == "generator" else CounterNoise(seed)


@pytest.mark.parametrize("noise", NOISES)
@pytest.mark.parametrize("compiled", FLAT_PATHS)
@pytest.mark.parametrize("sensor", [Sensor(), Sensor(gain_db=12.0, read_noise_dn=3.0), Sensor(saturation_dn=1023)])
def test_flat_regions_from_the_table_equal_the_pixel_by_pixel_noise(sensor, compiled, noise, monkeypatch) -> None:
    monkeypatch.setattr(kernels, "AVAILABLE", compiled)
    rng = np.random.default_rng(3)
    canvas = np.full((120, 160), np.float32(40.0 * 10 ** (sensor.gain_db / 20)), np.float32)
    boxes = [(10, 60, 20, 90), (40, 110, 70, 150), None]  # the first two overlap
    for r0, r1, c0, c1 in boxes[:2]:
        canvas[r0:r1, c0:c1] = rng.uniform(0.0, 1.2 * sensor.saturation_dn, (r1 - r0, c1 - c0))
    canvas[:5, :5] = -3.0  # below zero and saturated values take the same paths in both
    boxes.append((0, 5, 0, 5))
    flat = expose(canvas.copy(), sensor, _noise(noise, 9), flat=(float(canvas[-1, 0]), boxes))
    plain = expose(canvas.copy(), sensor, _noise(noise, 9))
    assert flat.dtype == plain.dtype and np.array_equal(flat, plain)
    assert len(np.unique(flat[-30:, :15])) > 3  # the flat part is noisy, not a constant


@NO_KERNEL
@settings(max_examples=150, deadline=None)
@given(data=st.data(), sensor=st.sampled_from([Sensor(), Sensor(gain_db=18.0, read_noise_dn=4.0),
                                               Sensor(saturation_dn=4095, full_well_e=3000.0)]),
       noise=st.sampled_from(NOISES))
def test_the_compiled_exposure_is_the_numpy_one_bit_for_bit_property(data, sensor, noise) -> None:
    """Any window size, level and set of boxes (overlapping, touching the edges, empty, None), either noise: the
    kernel gives the numpy path's image and leaves the canvas as it was."""
    h, w = data.draw(st.integers(1, 60)), data.draw(st.integers(1, 80))
    level = data.draw(st.floats(0.0, 1.1 * sensor.saturation_dn, width=32))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32)))
    canvas = np.full((h, w), level, np.float32)
    edges = st.tuples(st.integers(0, h), st.integers(0, h), st.integers(0, w), st.integers(0, w))
    boxes = [None if b is None else (min(b[:2]), max(b[:2]), min(b[2:]), max(b[2:]))
             for b in data.draw(st.lists(st.one_of(st.none(), edges), max_size=4))]
    for box in boxes:
        if box is not None:
            r0, r1, c0, c1 = box
            canvas[r0:r1, c0:c1] = rng.uniform(-5.0, 1.3 * sensor.saturation_dn, (r1 - r0, c1 - c0))
    seed = int(rng.integers(2**32))
    before = canvas.copy()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(kernels, "AVAILABLE", False)
        expected = expose(canvas.copy(), sensor, _noise(noise, seed), flat=(level, boxes))
    got = expose(canvas, sensor, _noise(noise, seed), flat=(level, boxes))
    assert got.dtype == expected.dtype and np.array_equal(got, expected)
    assert np.array_equal(canvas, before)


@NO_KERNEL
def test_the_compiled_exposure_refuses_mismatched_arrays() -> None:
    signal, draws = np.zeros((4, 5), np.float32), np.zeros((5, 4), np.uint16)
    table = np.zeros(65536, np.uint8)
    with pytest.raises(ValueError, match="same 2-D shape"):
        kernels.expose_flat(signal, draws, table, [], table.astype(np.float32), *np.float32([0.1, 1.0, 255.49]))
    with pytest.raises(ValueError, match="65,536"):
        kernels.expose_flat(signal, draws.T, table[:10], [], table.astype(np.float32), *np.float32([0.1, 1.0, 255.49]))


def test_uniform16_draws_every_value_evenly_and_reproducibly() -> None:
    n = 1_000_003  # not a multiple of four
    a = uniform16(np.random.default_rng(5), n)
    assert a.dtype == np.uint16 and a.shape == (n,)
    assert np.array_equal(a, uniform16(np.random.default_rng(5), n))
    counts = np.bincount(a >> 8, minlength=256)  # the high byte: 256 cells of about 3,906
    chi2 = float(((counts - n / 256) ** 2 / (n / 256)).sum())
    assert 150 < chi2 < 380  # chi-square(255): P(< 150) = 2e-8, P(> 380) = 6e-7
    low = np.bincount(a & 0xFF, minlength=256)
    assert 150 < float(((low - n / 256) ** 2 / (n / 256)).sum()) < 380


def test_noise_matches_read_and_shot_noise(guestrin):
    *_, outline = guestrin
    sample = outline[0, 0, 0, 4]
    sensor = Sensor()
    clean = render_roi(sample, np.random.default_rng(0), settings=RenderSettings(sensor=sensor.noiseless())).image
    noisy = render_roi(sample, np.random.default_rng(0)).image
    skin = Appearance().skin_dn
    expected = np.sqrt(sensor.read_noise_dn**2 + skin * sensor.saturation_dn / sensor.full_well_e)
    flat = clean == round(skin)
    assert flat.mean() > 0.5
    measured = np.std(noisy[flat].astype(float) - skin)
    assert measured == pytest.approx(np.sqrt(expected**2 + 1 / 12), rel=0.05)  # + quantisation


def test_glints_are_small_saturated_spots_at_their_ground_truth(guestrin):
    *_, outline = guestrin
    frame = render_roi(outline[0, 0, 0, 4], np.random.default_rng(0))
    truth = frame.truth
    assert truth.glint_visible.all()
    for gx, gy in truth.glint_px[0] - frame.roi_xy:
        patch = frame.image[round(gy) - 6:round(gy) + 7, round(gx) - 6:round(gx) + 7]
        saturated = np.count_nonzero(patch == 255)
        assert 4 <= saturated <= 30  # a plateau of roughly 2 to 6 px across
        rows, cols = np.nonzero(patch == 255)
        assert abs(cols.mean() - 6 - (gx - round(gx))) < 0.5 and abs(rows.mean() - 6 - (gy - round(gy))) < 0.5


def test_region_of_interest_is_a_crop_of_the_full_frame(guestrin):
    *_, outline = guestrin
    sample = outline[2, 0, 0, 4]
    settings = RenderSettings(sensor=Sensor().noiseless())
    full = render_full(sample, np.random.default_rng(0), settings=settings)
    roi = render_roi(sample, np.random.default_rng(0), settings=settings)
    x0, y0 = roi.roi_xy
    assert full.image.shape == (480, 640) and full.roi_xy == (0, 0)
    np.testing.assert_allclose(roi.image, full.image[y0:y0 + 240, x0:x0 + 320], atol=1)
    np.testing.assert_array_equal(roi.truth.pupil_centre_px, full.truth.pupil_centre_px)


def test_roi_window_stays_on_the_sensor():
    assert roi_window(np.array([5.0, 470.0]), (320, 240), (640, 480)) == (0, 240)
    assert roi_window(np.array([320.0, 240.0]), (320, 240), (640, 480)) == (160, 120)
    assert roi_window(np.array([np.nan, np.nan]), (320, 240), (640, 480)) == (160, 120)
    with pytest.raises(ValueError, match="larger than the sensor"):
        roi_window(np.zeros(2), (800, 240), (640, 480))


def test_render_features_yields_every_sample_and_both_eyes_in_full_frames():
    scene = load_scene("blignaut2014")
    eyes = published_eyes()[:1]
    features = simulate(eyes, scene, targets=scene.targets()[:2])
    rng = np.random.default_rng(0)
    rois = list(render_features(features, eyes, scene, rng))
    assert [k for k, _ in rois] == [(0, s, 0, t) for s in range(2) for t in range(2)]
    fulls = list(render_features(features, eyes, scene, rng, roi=None))
    assert [k for k, _ in fulls] == [(0, 0, 0), (0, 0, 1)]
    frame = fulls[0][1]
    assert frame.image.shape == (1200, 1600) and frame.truth.pupil_centre_px.shape == (2, 2)
    right, left = frame.truth.pupil_centre_px
    assert right[0] < left[0]  # the right eye appears on the image's left


def test_cli_render_writes_pngs_and_truth(tmp_path, capsys):
    import cv2

    from eyehil.cli import main

    assert main(["render", "-o", str(tmp_path), "--count", "2"]) == 0
    pngs = sorted(tmp_path.glob("*.png"))
    assert len(pngs) == 2 and cv2.imread(str(pngs[0]), cv2.IMREAD_UNCHANGED).shape == (240, 320)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert [f["file"] for f in truth["frames"]] == [p.name for p in pngs]
    assert "wrote" in capsys.readouterr().out
    assert main(["render", "-o", str(tmp_path), "--roi", "big"]) == 2
