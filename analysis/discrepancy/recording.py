"""Measured data as recordings: eyehil recordings (docs/recording.md) of real or simulated subjects turned
into per-subject conditions at the feature level and at the gaze-error level.

Convention (the recording format lets writers add keys; readers ignore unknown ones): one recording per
subject; the header's `"scene"` names the scene preset (default: the experiment's); target record
`target_id` = h * T + t for head position h and target t of that scene (so the head position of every
sample is known from its target label); `label` is free text ("<head name>/<t>"). A sample holds a record of
every eye the scene tracks (`"eye"` 0 right, 1 left: Guestrin 2006 the right eye, Blignaut 2014 both). Per eye,
samples whose pupil flag has DETECTED and every glint VALID count; a fixation's features are the mean over its
samples (the emulator's features are fixation means too).

Feature conditions (`feature_conditions`, per eye and head position <h>, px; every head position other
than the first is compared within subjects to the first, like the gaze conditions):

- `pgv_x:<h>`, `pgv_y:<h>`: the pupil-glint vector (pupil centre minus the glints' mean), mean over targets;
- `gain_x:<h>`, `gain_y:<h>`: its least-squares slope against the target's screen x / y (px per 100 mm):
  how far the pupil moves relative to the glints per unit of gaze, which the corneal shape, the pupil's
  position and the camera set;
- `glint_spacing:<h>`: the distance between the first and last glint (px), mean over targets;
- `pupil_major:<h>` (px) and `pupil_ratio:<h>` (minor / major axis), means over targets;
- `spacing_sd:<h>`: the SD over targets of the glint spacing about its least-squares plane in the target's screen
  x and y (px): per-fixation noise on each glint centre shows here, an eye rotation or a head movement, which move
  the glints together, barely;
- `spacing_perp_sd:<h>`: the same for the component of the vector from the last glint to the first across its mean
  direction (px): noise on each glint centre turns that vector; a head movement (nearer or farther, which scales it)
  and an eye rotation (which moves both glints) barely do, so feature noise cannot be mimicked here by a fixation
  error with head jitter. With one LED both spacing conditions are 0;
- `pgv_sd:<h>`: the SD over targets of the pupil-glint vector about its least-squares planes in x and y (px, x and
  y pooled): per-fixation scatter of the features, of the gaze (fixation error) and of the head.

The gaze conditions (H1, head:*, bias_*) come from running the host's own calibration on the recorded
features (`eyehil.analysis.discrepancy.metrics`), exactly as for the simulated eyes.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from eyehil.drivers.recording import FORMAT, VERSION, Recording
from eyehil.emulator.features import Features, empty_features
from eyehil.emulator.scene import Scene, load_scene
from eyehil.protocols.enums import Eye

QUANTITIES = ("pgv_x", "pgv_y", "gain_x", "gain_y", "glint_spacing", "pupil_major", "pupil_ratio", "spacing_sd",
              "spacing_perp_sd", "pgv_sd")
DETECTED, GLINT_VALID = 0x01, 0x01
EYE_IDS = {"right": int(Eye.RIGHT), "left": int(Eye.LEFT)}  # a side's `"eye"` in a recording's eye records


def feature_conditions(features: Features, side: str = "right") -> dict[str, np.ndarray]:
    """Per-eye feature conditions (module docstring), each (E,)."""
    s = features.sides.index(side)
    valid = features.valid[:, s]
    pupil = np.where(valid[..., None], features.pupil_centre_px[:, s], np.nan)
    glints = np.where(valid[..., None, None], features.glint_px[:, s], np.nan)
    axes = np.where(valid[..., None], features.pupil_axes_px[:, s], np.nan)
    pgv = pupil - glints.mean(axis=-2)
    between = glints[..., 0, :] - glints[..., -1, :]
    spacing = np.linalg.norm(between, axis=-1)
    tx, ty = (features.targets[:, i] - features.targets[:, i].mean() for i in (0, 1))
    plane = np.stack([np.ones_like(tx), tx, ty], axis=-1)  # (T, 3): the scatter conditions' least-squares plane
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        along = np.nanmean(between, axis=-2, keepdims=True)  # (E, H, 1, 2): the mean direction per head position
        along = along / np.maximum(np.linalg.norm(along, axis=-1, keepdims=True), 1e-12)
        across = between[..., 1] * along[..., 0] - between[..., 0] * along[..., 1]
        for h, head in enumerate(features.head_positions):
            name = getattr(head, "name", str(h))
            out[f"pgv_x:{name}"] = np.nanmean(pgv[:, h, :, 0], axis=-1)
            out[f"pgv_y:{name}"] = np.nanmean(pgv[:, h, :, 1], axis=-1)
            for key, t, c in (("gain_x", tx, 0), ("gain_y", ty, 1)):
                v = pgv[:, h, :, c]
                ok = np.isfinite(v)
                vc = v - np.nanmean(v, axis=-1, keepdims=True)
                out[f"{key}:{name}"] = 100.0 * np.nansum(np.where(ok, vc * t, 0), axis=-1) / np.maximum(
                    np.sum(np.where(ok, t * t, 0), axis=-1), 1e-12)
            out[f"glint_spacing:{name}"] = np.nanmean(spacing[:, h], axis=-1)
            out[f"pupil_major:{name}"] = np.nanmean(axes[:, h, :, 0], axis=-1)
            out[f"pupil_ratio:{name}"] = np.nanmean(axes[:, h, :, 1] / axes[:, h, :, 0], axis=-1)
            out[f"spacing_sd:{name}"] = np.sqrt(_plane_residual(spacing[:, h], plane))
            out[f"spacing_perp_sd:{name}"] = np.sqrt(_plane_residual(across[:, h], plane))
            ssr_x, ssr_y = (_plane_residual(pgv[:, h, :, c], plane) for c in (0, 1))
            out[f"pgv_sd:{name}"] = np.sqrt(0.5 * (ssr_x + ssr_y))
    return out


def _plane_residual(v: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Per eye, the residual variance (unbiased, n - 3 dof) of v (E, T) about its least-squares fit on the columns
    of `plane` (T, 3), over the finite values; NaN with fewer than 4."""
    ok = np.isfinite(v)
    w = ok.astype(float)
    y = np.where(ok, v, 0.0)
    normal = np.einsum("et,ti,tj->eij", w, plane, plane)
    rhs = np.einsum("et,ti,et->ei", w, plane, y)
    n = ok.sum(axis=-1)
    good = n >= plane.shape[1] + 1
    beta = np.zeros((len(v), plane.shape[1]))
    if good.any():
        beta[good] = np.linalg.solve(normal[good], rhs[good][..., None])[..., 0]
    residual = np.where(ok, y - beta @ plane.T, 0.0)
    return np.where(good, (residual**2).sum(axis=-1) / np.maximum(n - plane.shape[1], 1), np.nan)


def feature_names(head_positions) -> list[str]:
    """The names `feature_conditions` gives for these head positions (every quantity at each)."""
    return [f"{q}:{getattr(h, 'name', str(i))}" for i, h in enumerate(head_positions) for q in QUANTITIES]


def feature_reference(condition: str, first_head: str = "central") -> str | None:
    """A feature condition at another head position is compared to the same quantity at the first."""
    quantity, colon, head = condition.partition(":")
    if colon and quantity in QUANTITIES and head != first_head:
        return f"{quantity}:{first_head}"
    return None


def write_recording(path: str | Path, features: Features, eye: int, *, samples: int = 3,
                    frame_noise_px: float = 0.0, rng: np.random.Generator | None = None) -> Path:
    """Eye `eye` of simulated `features` as a recording (the convention above), every side the features hold (an
    eye record each); each fixation becomes `samples` samples with independent Gaussian noise of `frame_noise_px`
    on every centre."""
    path = Path(path)
    scene = load_scene(features.scene)
    rng = rng or np.random.default_rng(0)
    H, T = features.shape[2], features.shape[3]
    w, h_mm = scene.screen.size
    lines = [{"format": FORMAT, "version": VERSION, "created": "1970-01-01T00:00:00+00:00", "url": "simulated",
              "note": "eyehil discrepancy: simulated subject", "device": None, "configuration": None,
              "clock_sync": None, "host_clock": "monotonic, us", "scene": features.scene, "subject": f"eye{eye + 1}"}]
    clock, seq = 0, 0
    for h in range(H):
        for t in range(T):
            clock += 1000
            target = features.targets[t] - scene.screen.centre
            lines.append({"type": "target", "host_us": clock, "device_us": clock, "target_id": h * T + t,
                          "x_mm": float(w / 2 - target[0]), "y_mm": float(h_mm / 2 - target[1]), "visible": True,
                          "label": f"{getattr(features.head_positions[h], 'name', h)}/{t}"})
            for _ in range(samples):
                clock += 4000
                seq += 1
                records = [_eye_record(features, (eye, s, h, t), EYE_IDS[side], frame_noise_px, rng)
                           for s, side in enumerate(features.sides)]
                lines.append({"type": "sample", "seq": seq, "frame_id": seq, "device_us": clock, "host_us": clock,
                              "lost_before": 0, "skipped_before": 0, "target_id": h * T + t, "eyes": records})
    lines.append({"type": "end", "host_us": clock, "samples": seq, "stats": {}, "status": None})
    path.write_text("".join(json.dumps(x) + "\n" for x in lines), encoding="utf-8")
    return path


def _eye_record(features: Features, at: tuple[int, int, int, int], eye_id: int, noise_px: float,
                rng: np.random.Generator) -> dict:
    """The recording's record of one eye of one sample: fixation `at` (eye, side, head, target) of `features`, with
    Gaussian noise of `noise_px` on every centre."""
    ok = bool(features.valid[at])
    centre = features.pupil_centre_px[at] + noise_px * rng.standard_normal(2)
    glints = features.glint_px[at] + noise_px * rng.standard_normal((features.glint_px.shape[-2], 2))
    return {"eye": eye_id, "flags": DETECTED if ok else 0, "centre": [float(v) for v in np.nan_to_num(centre)],
            "axes": [float(v) for v in np.nan_to_num(features.pupil_axes_px[at])],
            "angle_deg": float(np.nan_to_num(features.pupil_angle_deg[at])), "confidence": 1.0 if ok else 0.0,
            "glints": [{"led": k, "flags": GLINT_VALID if ok else 0, "x": float(np.nan_to_num(g[0])),
                        "y": float(np.nan_to_num(g[1]))} for k, g in enumerate(glints)]}


def recorded_features(recordings: Mapping[str, Recording], scene: Scene) -> Features:
    """Fixation-mean features (E = one per recording, every side `scene` tracks, H, T) of recordings of `scene`, read
    (`read_recording`) and named (their paths, for the messages)."""
    H, T, L = len(scene.head_positions), len(scene.targets()), len(scene.leds)
    out = empty_features(len(recordings), scene, tuple(scene.head_positions), T, 1, scene.targets(), "recorded")
    for e, (path, rec) in enumerate(recordings.items()):
        if rec.header.get("scene", scene.name) != scene.name:
            raise ValueError(f"{path}: recorded in scene {rec.header['scene']!r}, expected {scene.name!r}")
        if len(rec) == 0:
            raise ValueError(f"{path}: no samples")
        if rec.glints.shape[2] < L:
            raise ValueError(f"{path}: {rec.glints.shape[2]} glints per sample, the scene has {L} LEDs")
        ids = rec.target_id
        if np.any(ids >= H * T):
            raise ValueError(f"{path}: target_id beyond the scene's {H} x {T} fixations")
        for s, side in enumerate(scene.sides):
            column = np.nonzero(rec.eyes == EYE_IDS[side])[0]
            if not len(column):
                raise ValueError(f"{path}: no {side} eye recorded; scene {scene.name!r} tracks "
                                 f"{' and '.join(scene.sides)}")
            j = int(column[0])
            good = (rec.pupil_flags[:, j] & DETECTED).astype(bool) & np.all(
                (rec.glint_flags[:, j, :L] & GLINT_VALID).astype(bool), axis=-1) & (ids >= 0)
            fixation = ids[good]
            count = np.bincount(fixation, minlength=H * T).reshape(H, T)
            seen = count > 0
            for name, values in (("pupil_centre_px", rec.centre[:, j]), ("pupil_axes_px", rec.axes[:, j]),
                                 ("glint_px", rec.glints[:, j, :L])):
                sums = np.zeros((H * T, *values.shape[1:]))
                np.add.at(sums, fixation, values[good])
                means = sums.reshape(H, T, *values.shape[1:]) / np.maximum(count, 1).reshape(
                    H, T, *([1] * (values.ndim - 1)))
                out.arrays[name][e, s][seen] = means[seen]
            for name in ("pupil_valid", "glint_valid", "fixation_valid"):  # glint_valid has one per LED
                flags = out.arrays[name][e, s]
                flags[...] = seen.reshape(H, T, *([1] * (flags.ndim - 2)))
    return out
