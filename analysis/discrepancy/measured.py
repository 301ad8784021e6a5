"""Measured data from wherever it comes: a built-in published data set, a measured-data file, or a folder of
recordings (one per subject), compared at the gaze-error and the feature level (docs/discrepancy.md).

`measured_from_spec` is what `eyehil discrepancy --measured` takes; `load_recordings` reads a folder of eyehil
recordings (`recording`) into per-subject conditions of the experiment (`metrics`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from eyehil.analysis.discrepancy.data import BUILTIN, Measured, MeasuredCondition, load
from eyehil.analysis.discrepancy.metrics import experiment as get_experiment
from eyehil.analysis.discrepancy.recording import feature_conditions, recorded_features
from eyehil.emulator.scene import load_scene


def measured_from_spec(spec: str) -> Measured:
    """A built-in data set by name (guestrin2006, blignaut2014), a folder of recordings (one *.jsonl per
    subject, `eyehil.analysis.discrepancy.recording`) or a measured-data file path."""
    if spec in BUILTIN:
        return BUILTIN[spec]()
    if Path(spec).is_dir():
        return load_recordings(spec)
    return load(spec)


def measured_from_recordings(paths: Sequence[str | Path], experiment: str = "guestrin2006",
                             source: str = "") -> Measured:
    """Per-subject gaze and feature conditions of recordings (one per subject), paired by subject."""
    if experiment != "guestrin2006":
        raise ValueError("recordings are supported for the guestrin2006 experiment only")
    if len(paths) < 2:
        raise ValueError("measured recordings: at least 2 subjects")
    exp = get_experiment(experiment)
    scene = load_scene(exp.scene)
    features = recorded_features(paths, scene)
    metrics = exp.metrics([features], scene)[0]
    names = [*exp.diagnostic_conditions(scene), *feature_conditions(features)]
    values = np.array([metrics[c] for c in names])
    keep = np.all(np.isfinite(values), axis=0)
    if keep.sum() < 2:
        raise ValueError("measured recordings: fewer than 2 subjects with every condition")
    subjects = tuple(Path(p).stem for p, k in zip(paths, keep, strict=True) if k)
    data = {c: MeasuredCondition.of(v[keep]) for c, v in zip(names, values, strict=True)}
    return Measured(experiment, data, subjects, source or f"{len(subjects)} recordings", {})


def load_recordings(folder: str | Path, experiment: str = "guestrin2006") -> Measured:
    """Every *.jsonl recording in `folder` (sorted by name), one per subject."""
    paths = sorted(Path(folder).glob("*.jsonl"))
    if not paths:
        raise FileNotFoundError(f"no *.jsonl recordings in {folder}")
    return measured_from_recordings(paths, experiment, f"recordings in {folder}")
