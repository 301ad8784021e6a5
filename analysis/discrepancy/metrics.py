"""The experiments the discrepancy workflow compares with measured data, and a batched evaluator.

An experiment turns features into per-eye conditions (degrees, one array (E,) per condition name):

- guestrin2006 (scene `guestrin2006`, right eye, 9 targets x 5 head positions): "H1", "H2",
  "head:<name>", "bias_x:H1|H2", "bias_y:H1|H2" (`eyehil.analysis.discrepancy.guestrin`); H2 and head:* have
  the reference H1 (compared within subjects when the measured data are paired).
- blignaut2014 (scene `blignaut2014`, binocular, 135 targets, one head position): "C5" ... "C135", each
  eye's error under the configuration's best function (the model of lowest mean error over the simulated
  eyes, as `eyehil.analysis.study.summary`), and "M<k>:<configuration>" for model k; no references.

`Evaluator` simulates a fixed set of eyes with the base effects plus each point's extra effects (every
point with the same Generator seed: common random numbers; a session that no extra effect can change is
reused from the base), and runs the experiment on all points together (Guestrin: one batched calibration,
warm-started from the base fit). The host always keeps the nominal scene.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace

import numpy as np

from eyehil.analysis.discrepancy.guestrin import guestrin_metrics
from eyehil.analysis.study import experiments
from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.analysis.study.summary import best_functions
from eyehil.drivers.gaze.forms import MODELS
from eyehil.emulator.effects import Applied
from eyehil.emulator.effects.run import join_heads, perturb, sessions, simulate_session
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene, load_scene

Metrics = dict[str, np.ndarray]


class GuestrinExperiment:
    """Guestrin & Eizenman 2006 as the published replication ran it."""

    name = "guestrin2006"
    scene = "guestrin2006"

    def reference(self, condition: str) -> str | None:
        return "H1" if condition == "H2" or condition.startswith("head:") else None

    def diagnostic_conditions(self, host: Scene) -> tuple[str, ...]:
        """H1, the error at each moved head position, and the signed mean error over them (x, y)."""
        return ("H1", *(f"head:{h.name}" for h in host.head_positions[1:]), "bias_x:H2", "bias_y:H2")

    def metrics(self, features: Sequence[Features], host: Scene, start: np.ndarray | None = None) -> list[Metrics]:
        n = features[0].shape[0]
        arrays = {k: np.concatenate([f.arrays[k] for f in features]) for k in features[0].arrays}
        joined = replace(features[0], arrays=arrays)
        tiled = None if start is None else np.tile(start, (len(features), 1))
        out, _ = guestrin_metrics(joined, host, start=tiled)
        return [{k: v[i * n:(i + 1) * n] for k, v in out.items()} for i in range(len(features))]

    def base_parameters(self, features: Features, host: Scene) -> np.ndarray:
        """Calibrated parameters (E, 4) of the base features: the warm start of later points."""
        return guestrin_metrics(features, host)[1]


class BlignautExperiment:
    """Blignaut 2014 as the published replication ran it (8 models x 6 configurations)."""

    name = "blignaut2014"
    scene = "blignaut2014"

    def reference(self, condition: str) -> str | None:
        return None

    def diagnostic_conditions(self, host: Scene) -> tuple[str, ...]:
        return CONFIGURATIONS

    def metrics(self, features: Sequence[Features], host: Scene, start: np.ndarray | None = None) -> list[Metrics]:
        return [self._one(f, host) for f in features]

    def base_parameters(self, features: Features, host: Scene) -> None:
        return None

    def _one(self, features: Features, host: Scene) -> Metrics:
        errors = experiments.blignaut(features, host).errors
        models = sorted(MODELS)
        best = best_functions(errors)
        out = {c: errors[:, models.index(best[c]["model"]), i] for i, c in enumerate(CONFIGURATIONS)}
        for m, k in enumerate(models):
            out.update({f"M{k}:{c}": errors[:, m, i] for i, c in enumerate(CONFIGURATIONS)})
        return out


EXPERIMENTS = {"guestrin2006": GuestrinExperiment, "blignaut2014": BlignautExperiment}


def experiment(name: str) -> GuestrinExperiment | BlignautExperiment:
    if name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {name!r}; known: {', '.join(EXPERIMENTS)}")
    return EXPERIMENTS[name]()


@dataclass(frozen=True, eq=False)
class Setup:
    """What an evaluation needs (picklable: it travels to worker processes)."""

    experiment: str
    eyes: EyeModel
    host: Scene
    base: tuple[Applied, ...]
    seed: int
    cache: dict[str, Features]  # base features (before perturb) per session
    start: np.ndarray | None  # warm start of the calibration (Guestrin), (E, 4)


def evaluate_points(setup: Setup, points: Sequence[Sequence[Applied]]) -> list[Metrics]:
    """Conditions for every point (a list of extra effects each); sessions the extra effects cannot change
    come from the cache; the same Generator seed for every point."""
    features = []
    for extra in points:
        applied = [*setup.base, *extra]
        parts = [simulate_session(setup.eyes, setup.host, applied, session, heads)
                 if any(a.effect.acts_in(session) for a in extra) else setup.cache[session]
                 for session, heads in sessions(setup.host)]
        features.append(perturb(join_heads(parts, setup.host), applied, np.random.default_rng(setup.seed)))
    return experiment(setup.experiment).metrics(features, setup.host, setup.start)


class Evaluator:
    """Per-eye conditions of `eyes` under `base` effects plus extra effects, batched over points.

    With a process `pool` (concurrent.futures), a batch of points is split among its workers."""

    def __init__(self, experiment_name: str, eyes: EyeModel, *, base: Sequence[Applied] = (), seed: int = 0,
                 pool: Executor | None = None, workers: int = 1):
        self.experiment = experiment(experiment_name)
        self.host = load_scene(self.experiment.scene)
        self.eyes, self.base, self.seed = eyes.as_batch(), tuple(base), seed
        self.pool, self.workers = pool, workers
        cache = {session: simulate_session(self.eyes, self.host, self.base, session, heads)
                 for session, heads in sessions(self.host)}
        setup = Setup(experiment_name, self.eyes, self.host, self.base, seed, cache, None)
        features = perturb(join_heads(list(cache.values()), self.host), self.base, np.random.default_rng(seed))
        start = self.experiment.base_parameters(features, self.host)
        self.setup = replace(setup, start=start)
        self.base_metrics = self.experiment.metrics([features], self.host, start)[0]

    def with_base(self, base: Sequence[Applied]) -> Evaluator:
        """The same eyes, seed and pool with other base effects."""
        return Evaluator(self.experiment.name, self.eyes, base=base, seed=self.seed, pool=self.pool,
                         workers=self.workers)

    def evaluate(self, points: Sequence[Sequence[Applied]],
                 progress: Callable[[int], None] | None = None) -> list[Metrics]:
        """Conditions for every point (a list of extra effects each)."""
        if self.pool is None or self.workers < 2 or len(points) < 2:
            out = evaluate_points(self.setup, points)
        else:
            parts = [list(c) for c in np.array_split(np.arange(len(points)), self.workers) if len(c)]
            futures = [self.pool.submit(evaluate_points, self.setup, [points[i] for i in c]) for c in parts]
            out = [m for f in futures for m in f.result()]
        if progress is not None:
            progress(len(points))
        return out
