"""The experiments the discrepancy workflow compares with measured data, and a batched evaluator.

An experiment turns features into per-eye conditions (degrees, one array (E,) per condition name):

- guestrin2006 (scene `guestrin2006`, right eye, 9 targets x 5 head positions): "H1", "H2",
  "head:<name>", "bias_x:H1|H2", "bias_y:H1|H2" (`eyehil.analysis.discrepancy.guestrin`); H2 and head:* have
  the reference H1 (compared within subjects when the measured data are paired); and the feature
  conditions of `eyehil.analysis.discrepancy.recording` (pupil-glint vectors and gains, glint spacing, pupil
  size and shape per head position, referred to the central position).
- blignaut2014 (scene `blignaut2014`, binocular, 135 targets, one head position): "C5" ... "C135", each
  eye's error under the configuration's best function (the model of lowest mean error over the simulated
  eyes, as `eyehil.analysis.study.summary`), and "M<k>:<configuration>" for model k; and the right eye's
  feature conditions at its one head position (no references).

`Evaluator` simulates a fixed set of eyes with the base effects plus each point's extra effects (every
point with the same Generator seed: common random numbers; a session that no extra effect can change is
reused from the base), and runs the experiment on all points together (Guestrin: one batched calibration,
warm-started from the base fit; a point whose extra effects act only at the validation head positions
and draw no random numbers has the base's calibration session, so it reuses the base's calibrated
parameters instead of calibrating again). A point's conditions do not depend on the other points of its batch, so
an evaluator given a `Memo` keeps them, keyed by what determines them (experiment, eyes, base effects, seed and
the point's effects and values), and evaluates only points it has not seen: the workflow's first-round screen
(the same nodes of every effect on the same search eyes) is evaluated once for many runs on one set of model eyes
(the blind trials). Effects that act through their features' sensitivity
(`eyehil.emulator.effects.subject`) have it computed once per evaluator, in the parent process, and cached.
The host always keeps the nominal scene. The evaluator traces `PUPIL_POINTS` points of each pupil's boundary
(the ellipse fitted through them gives the pupil centre, axes and angle within 1e-8 px of a default 30-point
trace on the published eyes, at half the cost; the glint occlusion reads the fitted ellipse, not the points).
"""

from __future__ import annotations

import hashlib
import pickle
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, replace

import numpy as np

from eyehil.analysis.discrepancy.guestrin import START, error_conditions, guestrin_metrics
from eyehil.analysis.discrepancy.recording import feature_conditions, feature_reference
from eyehil.analysis.study import experiments
from eyehil.analysis.study.bridge import eye_samples, screen_targets, tracker_geometry
from eyehil.analysis.study.published import CONFIGURATIONS
from eyehil.analysis.study.summary import best_functions
from eyehil.drivers.gaze.forms import MODELS
from eyehil.drivers.gaze.guestrin import EyeParameters, point_of_gaze
from eyehil.emulator.effects import Applied
from eyehil.emulator.effects.run import join_heads, perturb, sensitivity, sessions, simulate_session
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.scene import Scene, load_scene

Metrics = dict[str, np.ndarray]

#: pupil boundary points ray-traced per fixation in the search and show steps
PUPIL_POINTS = 16


class GuestrinExperiment:
    """Guestrin & Eizenman 2006 as the published replication ran it."""

    name = "guestrin2006"
    scene = "guestrin2006"

    def reference(self, condition: str) -> str | None:
        if condition == "H2" or condition.startswith("head:"):
            return "H1"
        return feature_reference(condition)

    def diagnostic_conditions(self, host: Scene) -> tuple[str, ...]:
        """H1, the error at each moved head position, and the signed mean error over them (x, y)."""
        return ("H1", *(f"head:{h.name}" for h in host.head_positions[1:]), "bias_x:H2", "bias_y:H2")

    def metrics(self, features: Sequence[Features], host: Scene, start: np.ndarray | None = None,
                calibrated: Sequence[bool] | None = None) -> list[Metrics]:
        """Conditions of every features set; `calibrated[i]`: point i's calibration session is the base's,
        so `start` (the base fit) is its calibration."""
        reuse = [i for i in range(len(features)) if calibrated is not None and calibrated[i] and start is not None]
        fit = [i for i in range(len(features)) if i not in reuse]
        out: list[Metrics | None] = [None] * len(features)
        if fit:
            n = features[0].shape[0]
            arrays = {k: np.concatenate([features[i].arrays[k] for i in fit]) for k in features[0].arrays}
            tiled = None if start is None else np.tile(start, (len(fit), 1))
            joined, _ = guestrin_metrics(replace(features[0], arrays=arrays), host, start=tiled)
            for j, i in enumerate(fit):
                out[i] = {k: v[j * n:(j + 1) * n] for k, v in joined.items()}
        if reuse:
            n = features[0].shape[0]
            arrays = {k: np.concatenate([features[i].arrays[k] for i in reuse]) for k in features[0].arrays}
            joined = guestrin_metrics_at(replace(features[0], arrays=arrays), host, np.tile(start, (len(reuse), 1)))
            for j, i in enumerate(reuse):
                out[i] = {k: v[j * n:(j + 1) * n] for k, v in joined.items()}
        for i, f in enumerate(features):
            out[i].update(feature_conditions(f))  # type: ignore[union-attr]
        return out  # type: ignore[return-value]

    def base_parameters(self, features: Features, host: Scene) -> np.ndarray:
        """Calibrated parameters (E, 4) of the base features: the warm start of later points."""
        return guestrin_metrics(features, host)[1]


class BlignautExperiment:
    """Blignaut 2014 as the published replication ran it (8 models x 6 configurations; the fits batched over eyes)."""

    name = "blignaut2014"
    scene = "blignaut2014"

    def reference(self, condition: str) -> str | None:
        return feature_reference(condition)

    def diagnostic_conditions(self, host: Scene) -> tuple[str, ...]:
        return CONFIGURATIONS

    def metrics(self, features: Sequence[Features], host: Scene, start: np.ndarray | None = None,
                calibrated: Sequence[bool] | None = None) -> list[Metrics]:
        return [self._one(f, host) for f in features]

    def base_parameters(self, features: Features, host: Scene) -> None:
        return None

    def _one(self, features: Features, host: Scene) -> Metrics:
        errors = experiments.blignaut_batched(features, host).errors
        models = sorted(MODELS)
        best = best_functions(errors)
        out = {c: errors[:, models.index(best[c]["model"]), i] for i, c in enumerate(CONFIGURATIONS)}
        for m, k in enumerate(models):
            out.update({f"M{k}:{c}": errors[:, m, i] for i, c in enumerate(CONFIGURATIONS)})
        out.update(feature_conditions(features))  # the right eye's, as for Guestrin
        return out


def guestrin_metrics_at(features: Features, host: Scene, params: np.ndarray, side: str = "right") -> Metrics:
    """The conditions of `guestrin_metrics` for given calibrated parameters (E, 4) (NaN rows: not
    calibrated), without calibrating."""
    geometry, targets = tracker_geometry(host), screen_targets(host)
    s = eye_samples(features, side)
    ok = np.all(np.isfinite(params), axis=1)
    x = np.where(ok[:, None], params, START)
    estimate = point_of_gaze(geometry, s, EyeParameters(*(x[:, i][:, None, None] for i in range(4))))
    estimate = np.where(ok[:, None, None, None], estimate, np.nan)
    return error_conditions(estimate, targets, features.head_positions)


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
    sensitivities: dict[str, dict[str, np.ndarray]]  # per effect name (effects with needs_sensitivity)


def evaluate_points(setup: Setup, points: Sequence[Sequence[Applied]]) -> list[Metrics]:
    """Conditions for every point (a list of extra effects each); sessions the extra effects cannot change
    come from the cache; the same Generator seed for every point."""
    features, calibrated = [], []
    for extra in points:
        applied = [*setup.base, *extra]
        parts = [simulate_session(setup.eyes, setup.host, applied, session, heads, n_pupil_points=PUPIL_POINTS)
                 if any(a.effect.acts_in(session) for a in extra) else setup.cache[session]
                 for session, heads in sessions(setup.host)]
        features.append(perturb(join_heads(parts, setup.host), applied, np.random.default_rng(setup.seed),
                                setup.sensitivities))
        calibrated.append(all(a.effect.stage == "model" and a.effect.validation_only for a in extra))
    return experiment(setup.experiment).metrics(features, setup.host, setup.start, calibrated)


def applied_key(applied: Sequence[Applied]) -> tuple:
    """What identifies a list of applied effects: their names and values, in order."""
    return tuple((a.effect.name, tuple(sorted(a.values.items()))) for a in applied)


class Memo:
    """Evaluated points' conditions, at most `limit` points (the least recently used go first; a point of 16 eyes
    holds some 15 kB with its arrays' overhead, in either experiment with features). `hits` and `misses` count
    lookups."""

    def __init__(self, limit: int = 3000):
        if limit < 1:
            raise ValueError(f"a memo holds at least one point, got limit {limit}")
        self.limit, self.hits, self.misses = limit, 0, 0
        self._points: OrderedDict[Hashable, Metrics] = OrderedDict()

    def __len__(self) -> int:
        return len(self._points)

    def get(self, key: Hashable) -> Metrics | None:
        found = self._points.get(key)
        if found is None:
            self.misses += 1
            return None
        self.hits += 1
        self._points.move_to_end(key)
        return {k: np.array(v, copy=True) for k, v in found.items()}

    def put(self, key: Hashable, metrics: Metrics) -> None:
        self._points[key] = {k: np.array(v, copy=True) for k, v in metrics.items()}
        self._points.move_to_end(key)
        while len(self._points) > self.limit:
            self._points.popitem(last=False)


class Evaluator:
    """Per-eye conditions of `eyes` under `base` effects plus extra effects, batched over points.

    With a process `pool` (concurrent.futures), a batch of points is split among its workers; with a `memo`, points
    evaluated before (by this or any evaluator of the same experiment, eyes, base and seed) are not evaluated
    again."""

    def __init__(self, experiment_name: str, eyes: EyeModel, *, base: Sequence[Applied] = (), seed: int = 0,
                 pool: Executor | None = None, workers: int = 1, memo: Memo | None = None):
        self.experiment = experiment(experiment_name)
        self.host = load_scene(self.experiment.scene)
        self.eyes, self.base, self.seed = eyes.as_batch(), tuple(base), seed
        self.pool, self.workers, self.memo = pool, workers, memo
        self._key = None if memo is None else (
            experiment_name, hashlib.blake2b(pickle.dumps(self.eyes), digest_size=16).hexdigest(),
            applied_key(self.base), seed, PUPIL_POINTS)
        cache = {session: simulate_session(self.eyes, self.host, self.base, session, heads,
                                           n_pupil_points=PUPIL_POINTS)
                 for session, heads in sessions(self.host)}
        setup = Setup(experiment_name, self.eyes, self.host, self.base, seed, cache, None, {})
        self.setup = setup
        self._sensitivities(self.base)
        features = perturb(join_heads(list(cache.values()), self.host), self.base, np.random.default_rng(seed),
                           setup.sensitivities)
        start = self.experiment.base_parameters(features, self.host)
        self.setup = replace(setup, start=start)
        self.base_metrics = self.experiment.metrics([features], self.host, start)[0]

    def _sensitivities(self, applied: Sequence[Applied]) -> None:
        """Compute and cache the sensitivity of every effect of `applied` that needs one (base model: the
        base effects that act in the ray tracing)."""
        model = [a for a in self.base if not a.effect.needs_sensitivity]
        for a in applied:
            if a.effect.needs_sensitivity and a.effect.name not in self.setup.sensitivities:
                self.setup.sensitivities[a.effect.name] = sensitivity(a.effect, self.eyes, self.host, model)

    def with_base(self, base: Sequence[Applied]) -> Evaluator:
        """The same eyes, seed and pool with other base effects."""
        return Evaluator(self.experiment.name, self.eyes, base=base, seed=self.seed, pool=self.pool,
                         workers=self.workers, memo=self.memo)

    def evaluate(self, points: Sequence[Sequence[Applied]],
                 progress: Callable[[int], None] | None = None) -> list[Metrics]:
        """Conditions for every point (a list of extra effects each)."""
        keys = [(self._key, applied_key(p)) for p in points] if self.memo is not None else []
        found = [self.memo.get(k) for k in keys] if self.memo is not None else [None] * len(points)
        todo = [p for p, m in zip(points, found, strict=True) if m is None]
        new = iter(self._evaluate(todo) if todo else [])
        out = [m if m is not None else next(new) for m in found]
        if self.memo is not None:
            for k, m, old in zip(keys, out, found, strict=True):
                if old is None:
                    self.memo.put(k, m)
        if progress is not None:
            progress(len(points))
        return out

    def _evaluate(self, points: Sequence[Sequence[Applied]]) -> list[Metrics]:
        self._sensitivities([a for p in points for a in p])
        if self.pool is None or self.workers < 2 or len(points) < 2:
            return evaluate_points(self.setup, points)
        parts = [list(c) for c in np.array_split(np.arange(len(points)), self.workers) if len(c)]
        futures = [self.pool.submit(evaluate_points, self.setup, [points[i] for i in c]) for c in parts]
        return [m for f in futures for m in f.result()]
