"""Measured data from wherever it comes: a built-in published data set, a measured-data file, or a folder of
recordings (one per subject), compared at the gaze-error and the feature level (docs/discrepancy.md).

`measured_from_spec` is what `eyehil discrepancy --measured` takes; `load_recordings` reads a folder of eyehil
recordings (`recording`) into per-subject conditions of the experiment (`metrics`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from eyehil.analysis.discrepancy.data import BUILTIN, Measured, MeasuredCondition, load
from eyehil.analysis.discrepancy.metrics import EXPERIMENTS
from eyehil.analysis.discrepancy.metrics import experiment as get_experiment
from eyehil.analysis.discrepancy.recording import feature_conditions, recorded_features
from eyehil.drivers.recording import Recording, read_recording
from eyehil.emulator.scene import load_scene


def measured_from_spec(spec: str, experiment: str | None = None) -> Measured:
    """A built-in data set by name (guestrin2006, blignaut2014), a folder of recordings (one *.jsonl per
    subject, `eyehil.analysis.discrepancy.recording`; of `experiment`, default the one whose scene the recordings
    name) or a measured-data file path."""
    if spec in BUILTIN:
        return BUILTIN[spec]()
    if Path(spec).is_dir():
        return load_recordings(spec, experiment)
    return load(spec)


def recordings_experiment(recordings: Iterable[Recording]) -> str:
    """The experiment whose scene the recordings' headers name (`"scene"`), guestrin2006 if none names one;
    ValueError if they name different scenes, or a scene no experiment runs in."""
    by_scene = {cls.scene: name for name, cls in EXPERIMENTS.items()}
    scenes = {rec.header.get("scene") for rec in recordings} - {None}
    if len(scenes) > 1:
        raise ValueError(f"recordings of different scenes: {', '.join(sorted(map(str, scenes)))}")
    if not scenes:
        return "guestrin2006"
    scene = scenes.pop()
    if scene not in by_scene:
        raise ValueError(f"recordings of scene {scene!r}: the discrepancy experiments run in "
                         f"{', '.join(sorted(by_scene))}")
    return by_scene[scene]


def measured_from_recordings(paths: Sequence[str | Path], experiment: str | None = None,
                             source: str = "") -> Measured:
    """Per-subject gaze and feature conditions of recordings (one per subject), paired by subject; `experiment`
    (default: `recordings_experiment`) says which conditions: its diagnostic ones (Guestrin 2006's errors per head
    position, Blignaut 2014's per calibration configuration) and the feature conditions of the right eye."""
    if len(paths) < 2:
        raise ValueError("measured recordings: at least 2 subjects")
    recordings = {str(path): read_recording(path) for path in paths}
    experiment = experiment or recordings_experiment(recordings.values())
    exp = get_experiment(experiment)
    scene = load_scene(exp.scene)
    features = recorded_features(recordings, scene)
    metrics = exp.metrics([features], scene)[0]
    names = [*exp.diagnostic_conditions(scene), *feature_conditions(features)]
    values = np.array([metrics[c] for c in names])
    keep = np.all(np.isfinite(values), axis=0)
    if keep.sum() < 2:
        raise ValueError("measured recordings: fewer than 2 subjects with every condition")
    subjects = tuple(Path(p).stem for p, k in zip(paths, keep, strict=True) if k)
    data = {c: MeasuredCondition.of(v[keep]) for c, v in zip(names, values, strict=True)}
    return Measured(experiment, data, subjects, source or f"{len(subjects)} recordings", {})


def load_recordings(folder: str | Path, experiment: str | None = None) -> Measured:
    """Every *.jsonl recording in `folder` (sorted by name), one per subject, of `experiment` (default: the one
    their headers' scene names, `recordings_experiment`)."""
    paths = sorted(Path(folder).glob("*.jsonl"))
    if not paths:
        raise FileNotFoundError(f"no *.jsonl recordings in {folder}")
    return measured_from_recordings(paths, experiment, f"recordings in {folder}")
