"""Counter-based sensor noise: the 16-bit uniform draws of one image as a pure function of a 64-bit key.

`CounterNoise(key)` draws number i (i = 0, 1, ... in the image's row-major pixel order) as a 16-bit quarter of
SplitMix64's output for counter i // 4 (Steele, Lea & Flood 2014, "Fast splittable pseudorandom number
generators", OOPSLA; the finaliser is Stafford's "Mix13"): word j is

    z = key + (j + 1) * 0x9E3779B97F4A7C15     (mod 2**64)
    z = (z ^ z >> 30) * 0xBF58476D1CE4E5B9
    z = (z ^ z >> 27) * 0x94D049BB133111EB
    z ^ z >> 31

and draw 4j + q its bits [16q, 16q + 16) (little end first: the words viewed as uint16). Any draw can be had
without the ones before it, and no generator object is built per image: the device's images cost 25 us of
draws (the compiled kernel, `kernels.counter_draws`) where a seeded PCG64 cost 10 us to build and 45 to draw
(docs/benchmarks.md). The numpy path here gives the same draws bit for bit (tests/test_render_noise.py).

`exposure_key(seed, frame_id, eye)` chains the same finaliser over the three numbers, so every image of a
device has its own key. Anything else random in an image (eyelashes) comes from `generator`, a numpy
generator seeded with the key, built only when asked for.
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.render import kernels

GAMMA = 0x9E3779B97F4A7C15
_MASK = (1 << 64) - 1


def mix64(z: int) -> int:
    """SplitMix64's finaliser of the 64-bit integer `z` (Python ints)."""
    z &= _MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return z ^ (z >> 31)


def exposure_key(seed: int, frame_id: int, eye: int) -> int:
    """The 64-bit key of the image of `eye` of exposure `frame_id` on a device seeded `seed`."""
    return mix64(mix64(mix64(int(seed) + GAMMA) + int(frame_id)) + int(eye))


class CounterNoise:
    """The draws of one image (module docstring); `generator` for anything else random in it."""

    __slots__ = ("_generator", "key")

    def __init__(self, key: int) -> None:
        if not 0 <= int(key) <= _MASK:
            raise ValueError(f"a noise key is a 64-bit unsigned integer, got {key}")
        self.key = int(key)
        self._generator: np.random.Generator | None = None

    def uniform16(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """Draws 0 .. n-1 (uint16), into `out` (n,) if given."""
        if out is None:
            out = np.empty(n, np.uint16)
        if kernels.AVAILABLE:
            return kernels.counter_draws(self.key, out)
        out[:] = numpy_draws(self.key, n)
        return out

    @property
    def generator(self) -> np.random.Generator:
        """A numpy generator seeded with the key (built on first use)."""
        if self._generator is None:
            self._generator = np.random.default_rng(self.key)
        return self._generator

    def __repr__(self) -> str:
        return f"CounterNoise(0x{self.key:016x})"


def numpy_draws(key: int, n: int) -> np.ndarray:
    """The draws 0 .. n-1 of counter noise `key`, computed with numpy (what the compiled kernel gives)."""
    words = np.arange(1, -(-n // 4) + 1, dtype=np.uint64)
    words *= np.uint64(GAMMA)
    words += np.uint64(key)
    words ^= words >> np.uint64(30)
    words *= np.uint64(0xBF58476D1CE4E5B9)
    words ^= words >> np.uint64(27)
    words *= np.uint64(0x94D049BB133111EB)
    words ^= words >> np.uint64(31)
    return words.view(np.uint16)[:n]


Noise = np.random.Generator | CounterNoise  # what a renderer takes its randomness from


def generator_of(noise: Noise) -> np.random.Generator:
    """A numpy generator for `noise`: itself, or a counter noise's `generator`."""
    return noise.generator if isinstance(noise, CounterNoise) else noise


def uniform16(noise: Noise, n: int) -> np.ndarray:
    """`n` uniform 16-bit integers. From a numpy generator: its bit generator's raw 64-bit words, four to a word
    (ten times faster than `Generator.bytes`, which draws 32-bit integers and copies them into a bytes object);
    from a `CounterNoise`: its draws 0 .. n-1."""
    if isinstance(noise, CounterNoise):
        return noise.uniform16(n)
    return noise.bit_generator.random_raw(-(-n // 4)).view(np.uint16)[:n]
