"""The counter-based sensor noise (`eyehil.emulator.render.noise`): SplitMix64's outputs, the same compiled and in
numpy, uniform, independent between images, and a frame a function of its key."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.emulator.render import kernels
from eyehil.emulator.render.noise import CounterNoise, exposure_key, mix64, numpy_draws, uniform16

NO_KERNEL = pytest.mark.skipif(not kernels.AVAILABLE, reason=f"compiled kernel unavailable: {kernels.REASON}")


def _chi2(counts: np.ndarray) -> float:
    expected = counts.sum() / counts.size
    return float(((counts - expected) ** 2 / expected).sum())


def test_the_draws_are_splitmix64s_published_outputs() -> None:
    """SplitMix64 seeded with 0 starts 0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F (the reference
    implementation, Vigna's splitmix64.c); key 0's draws are those words, four 16-bit quarters each, low first."""
    words = np.array([0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F], np.uint64)
    assert np.array_equal(numpy_draws(0, 12), words.view(np.uint16))
    assert mix64(0x9E3779B97F4A7C15) == 0xE220A8397B1DCDAF


@NO_KERNEL
@pytest.mark.parametrize("n", [0, 1, 3, 4, 5, 7, 76_800, 307_201])
@pytest.mark.parametrize("key", [0, 1, 0xDEADBEEF, (1 << 64) - 1])
def test_the_compiled_draws_are_numpys(n: int, key: int) -> None:
    out = np.full(n, 0xABCD, np.uint16)
    assert np.array_equal(kernels.counter_draws(key, out), numpy_draws(key, n))


def test_keys_are_64_bit_and_the_kernel_takes_only_a_flat_uint16_array() -> None:
    with pytest.raises(ValueError, match="64-bit"):
        CounterNoise(1 << 64)
    with pytest.raises(ValueError, match="64-bit"):
        CounterNoise(-1)
    if kernels.AVAILABLE:
        with pytest.raises(ValueError, match="uint16"):
            kernels.counter_draws(1, np.zeros(8, np.int32))
        with pytest.raises(ValueError, match="uint16"):
            kernels.counter_draws(1, np.zeros((4, 4), np.uint16)[:, ::2].ravel()[::2])


def test_the_draws_are_uniform_and_successive_draws_independent() -> None:
    n = 1_000_003
    a = CounterNoise(exposure_key(3, 17, 1)).uniform16(n)
    assert a.shape == (n,) and a.dtype == np.uint16
    # chi-square(255): P(< 150) = 2e-8, P(> 380) = 6e-7
    assert 150 < _chi2(np.bincount(a >> 8, minlength=256)) < 380
    assert 150 < _chi2(np.bincount(a & 0xFF, minlength=256)) < 380
    pairs = (a[:-1] >> 12).astype(np.int64) * 16 + (a[1:] >> 12)  # neighbours, also across a word's quarters
    assert 150 < _chi2(np.bincount(pairs, minlength=256)) < 380


def test_images_of_neighbouring_exposures_eyes_and_seeds_have_unrelated_noise() -> None:
    n = 76_800
    base = CounterNoise(exposure_key(0, 1000, 1)).uniform16(n).astype(float)
    for seed, frame_id, eye in ((0, 1001, 1), (0, 1000, 2), (1, 1000, 1)):
        other = CounterNoise(exposure_key(seed, frame_id, eye)).uniform16(n).astype(float)
        assert abs(np.corrcoef(base, other)[0, 1]) < 4 / np.sqrt(n)  # 4 standard errors
    keys = {exposure_key(s, f, e) for s in range(3) for f in range(200) for e in range(3)}
    assert len(keys) == 3 * 200 * 3


def test_uniform16_takes_either_kind_of_noise() -> None:
    assert np.array_equal(uniform16(CounterNoise(9), 10), numpy_draws(9, 10))
    assert np.array_equal(uniform16(np.random.default_rng(5), 10), uniform16(np.random.default_rng(5), 10))


def test_the_numpy_generator_of_a_counter_noise_is_built_only_when_asked_and_is_reproducible() -> None:
    noise = CounterNoise(42)
    noise.uniform16(100)
    assert noise._generator is None
    assert noise.generator.random() == CounterNoise(42).generator.random()
