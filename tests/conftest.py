"""Shared fixtures: a few eyes and the scene presets; the blind trials' measured rates in the run's summary."""

from __future__ import annotations

import numpy as np
import pytest
from blind_rates import summarise

from eyehil.emulator.eye.biometry import eye_from_biometry
from eyehil.emulator.eye.model import EyeModel


def make_eyes(n: int = 4, seed: int = 0) -> EyeModel:
    """A small batch of plausible, varied eyes (not the Rozema population: a test fixture)."""
    rng = np.random.default_rng(seed)
    return eye_from_biometry(
        anterior_radius=rng.normal(7.8, 0.25, n), anterior_conic=rng.uniform(-0.5, 0.0, n),
        posterior_radius=rng.normal(6.5, 0.2, n), posterior_conic=rng.uniform(-0.4, 0.2, n),
        cct=rng.normal(0.545, 0.03, n), acd=rng.normal(2.9, 0.3, n), pupil_diameter=rng.uniform(3.0, 7.0, n),
        lens_anterior_radius=rng.normal(10.4, 1.0, n), lens_posterior_radius=rng.normal(6.9, 0.6, n),
        lens_thickness=rng.normal(4.0, 0.4, n), axial_length=rng.normal(23.7, 1.0, n), lens_index=1.42,
    )


@pytest.fixture
def eyes() -> EyeModel:
    return make_eyes()


@pytest.fixture(autouse=True)
def dask_scratch(tmp_path_factory):
    """Dask's scratch space (`temporary-directory`) under pytest's temporary root, not a shared
    /tmp/dask-scratch-space left behind by the suite; nothing when Dask (an optional extra) is not installed."""
    try:
        import dask
    except ImportError:
        yield
        return
    with dask.config.set({"temporary-directory": str(tmp_path_factory.getbasetemp() / "dask")}):
        yield


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """The blind trials' rates of every setting that ran, passed or not: the run's record of what was measured."""
    summarise(terminalreporter, config)
