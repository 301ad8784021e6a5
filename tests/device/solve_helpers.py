"""Solvers whose answers and timing a test controls, usable in a worker process (`solve_process.ProcessSolves`).

A worker process unpickles its solver by class name, so these live in a module the worker can import (this
folder is on `sys.path` in the tests, and the worker gets the device's `sys.path`).
"""

from __future__ import annotations

import os
import time

import numpy as np

from eyehil.emulator.device.solver import FeatureSolver
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.scene import load_scene

GENEROUS_S = 60.0  # only bounds a hang; never decides a result
FAILING_X = -999.0  # a single-point solve at this x raises ValueError("bad point")


def closed_form(xy: np.ndarray, n_eyes: int, n_channels: int) -> np.ndarray:
    """Cheap smooth non-linear features (N, E, C) of points (N, 2): interpolating them differs from the exact."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    base = np.concatenate([xy, xy**2 / 100.0], axis=1)
    values = np.tile(base[:, None, :1], (1, n_eyes, n_channels))
    values[..., 1] = base[:, None, 1]
    values[..., 2] = base[:, None, 2] + base[:, None, 3]
    return values


class HeldSolver(FeatureSolver):
    """Closed-form features; a single-point solve (a fixation) waits until the file `release` exists, in
    whichever process it runs (grids, many points at once, never wait)."""

    def __init__(self, release: os.PathLike | str) -> None:
        super().__init__(normative_eye("navarro"), load_scene("guestrin2006"))
        self.release = os.fspath(release)

    def solve(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, float).reshape(-1, 2)
        if len(xy) == 1:
            if xy[0, 0] == FAILING_X:
                raise ValueError("bad point")
            deadline = time.monotonic() + GENEROUS_S
            while not os.path.exists(self.release):
                if time.monotonic() > deadline:
                    raise RuntimeError("never released")
                time.sleep(0.005)  # a file another process writes: no event to wait on across processes
        return closed_form(xy, self.n_eyes, self.n_channels)
