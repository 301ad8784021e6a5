"""Host-side detection on synthetic frames: accuracy against the ray-traced ground truth over random eyes and
poses, an independent detector (Pupil Labs), calibration from frames against exact features, failures."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pytest

from eyehil.drivers.detect import FAILURES, detect_eye, detect_frame
from eyehil.drivers.detect.glints import match_leds
from eyehil.emulator.eye.population import sample
from eyehil.emulator.eye.published import published_eyes
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.render.geometry import eye_outlines
from eyehil.emulator.render.renderer import render_features, render_full, render_roi
from eyehil.emulator.scene import HeadPose, load_scene
from eyehil.protocols.enums import PupilFlags
from eyehil.protocols.samples import Features as FeaturesRecord

N_RANDOM = 220  # random eyes and poses per preset (>= 200)
TOLERANCE_PX = 0.1  # RMS, pupil centre and glints (issue 6)
LID_CLEARANCE_PX = 3.0  # glints closer to an eyelid are partly hidden; scored apart


@dataclass
class Scored:
    """Detections on random frames of one preset, against the ground truth."""

    pupil: list = field(default_factory=list)  # (dx, dy) px
    glint: list = field(default_factory=list)
    near_lid: list = field(default_factory=list)
    failures: Counter = field(default_factory=Counter)
    frames: list = field(default_factory=list)  # (image, roi_xy, truth centre, visible fraction)
    skipped: int = 0

    def rms(self, name: str) -> float:
        e = np.array(getattr(self, name)).reshape(-1, 2)
        return float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) if len(e) else np.nan

    def summary(self) -> str:
        reasons = "; ".join(f"{n} x {k}: {FAILURES.get(k, k)}" for k, n in self.failures.items()) or "none"
        return (f"{len(self.frames)} frames ({self.skipped} eyes without a pose on the sensor); pupil RMS "
                f"{self.rms('pupil'):.4f} px over {len(self.pupil)}, glint RMS {self.rms('glint'):.4f} px over "
                f"{len(self.glint)} (+{len(self.near_lid)} within {LID_CLEARANCE_PX:.0f} px of a lid: RMS "
                f"{self.rms('near_lid'):.3f} px); failures: {reasons}")


def random_poses(scene, n: int, rng: np.random.Generator):
    """Rozema eyes, each with one random head pose (x +-30, y +-20, z +-40 mm, yaw and pitch +-5 deg), target
    (uniform on the screen) and side, among the poses whose features fall on the sensor."""
    eyes = sample(n + 40, rng).eyes
    lo, hi = [-30, -20, -40, -5, -5], [30, 20, 40, 5, 5]
    heads = tuple(HeadPose(f"random {i}", *rng.uniform(lo, hi)) for i in range(4))
    size = np.asarray(scene.screen.size)
    targets = scene.screen.centre + np.column_stack([rng.uniform(-0.5, 0.5, (6, 2)) * size, np.zeros(6)])
    features = simulate(eyes, scene, targets=targets, head_positions=heads)
    picks, skipped = [], 0
    for e in range(len(eyes)):
        options = np.argwhere(features.visible[e])
        if len(options) == 0:
            skipped += 1
        elif len(picks) < n:
            picks.append((e, *options[rng.integers(len(options))]))
    return eyes, features, picks, skipped


@pytest.fixture(scope="module", params=["guestrin2006", "blignaut2014"])
def scored(request) -> tuple[str, Scored]:
    scene = load_scene(request.param)
    rng = np.random.default_rng(2024)
    eyes, features, picks, skipped = random_poses(scene, N_RANDOM, rng)
    out = Scored(skipped=skipped)
    leds = scene.leds[:, :2]
    for _, frame in render_features(features, eyes, scene, rng, index=picks):
        truth = frame.truth
        out.frames.append((frame.image, frame.roi_xy, truth.pupil_centre_px[0], truth.pupil_visible[0]))
        found = detect_eye(frame.image, len(leds), roi_xy=frame.roi_xy, led_xy_mm=leds)
        if found.failure:
            out.failures[found.failure] += 1
        if np.all(np.isfinite(found.pupil_px)):
            out.pupil.append(found.pupil_px - truth.pupil_centre_px[0])
        _score_glints(out, found.glints_px(len(leds)), truth)
    return request.param, out


def _score_glints(out: Scored, glints: np.ndarray, truth) -> None:
    for k, (xy, seen) in enumerate(zip(glints, truth.glint_visible[0], strict=True)):
        if not seen:
            continue
        if not np.all(np.isfinite(xy)):
            out.failures["glint_lost"] += 1
        elif truth.glint_lid_px[0, k] < LID_CLEARANCE_PX:
            out.near_lid.append(xy - truth.glint_px[0, k])
        else:
            out.glint.append(xy - truth.glint_px[0, k])


def test_detection_matches_the_ray_traced_features(scored):
    name, s = scored
    message = f"{name}: {s.summary()}"
    print(message)
    assert len(s.frames) >= 200, message
    assert s.rms("pupil") <= TOLERANCE_PX, message
    assert s.rms("glint") <= TOLERANCE_PX, message
    assert sum(s.failures.values()) <= 0.02 * len(s.frames), message  # failures are rare and all explained
    assert set(s.failures) <= set(FAILURES) | {"glint_lost"}, message


def test_pupil_labs_detector_agrees(scored):
    """Pupil Labs' 2D detector (pupil-detectors 2.0.2, wheels for CPython <= 3.11) on the same frames: its
    confident (>= 0.9) detections of fully visible pupils agree with the ground truth to the same order
    (RMS <= 0.3 px); it does not model eyelid occlusion, so partly hidden pupils are reported, not tested."""
    detectors = pytest.importorskip("pupil_detectors", reason="optional test dependency pupil-detectors "
                                    "(binary wheels for CPython 3.6-3.11 only) is not installed")
    name, s = scored
    detector = detectors.Detector2D({"coarse_detection": False, "pupil_size_max": 150})
    full, partial, failed = [], [], 0
    for image, roi_xy, centre, visible in s.frames:
        result = detector.detect(image)
        if result["confidence"] < 0.9:
            failed += 1
            continue
        error = np.array(result["ellipse"]["center"]) + roi_xy - centre
        (full if visible >= 0.999 else partial).append(error)
    rms = [float(np.sqrt(np.mean(np.sum(np.reshape(e, (-1, 2)) ** 2, 1)))) if e else np.nan for e in (full, partial)]
    message = (f"{name}: pupil-detectors RMS {rms[0]:.3f} px over {len(full)} fully visible pupils, {rms[1]:.3f} px "
               f"over {len(partial)} partly hidden; {failed} of {len(s.frames)} below confidence 0.9")
    print(message)
    assert len(full) >= 20, message
    assert rms[0] <= 3 * TOLERANCE_PX, message


def test_detection_is_robust_to_partial_eyelid_occlusion():
    scene = load_scene("guestrin2006")
    eyes = published_eyes()[:10]
    features = simulate(eyes, scene, head_positions=scene.head_positions[:1])
    errors, failures = [], Counter()
    for _, frame in render_features(features, eyes, scene, np.random.default_rng(3), blink=0.3):
        found = detect_eye(frame.image, 2, roi_xy=frame.roi_xy, led_xy_mm=scene.leds[:, :2])
        if found.failure:
            failures[found.failure] += 1
        if np.all(np.isfinite(found.pupil_px)):
            assert found.features.flags & PupilFlags.PARTIAL or frame.truth.pupil_visible[0] > 0.85
            errors.append(found.pupil_px - frame.truth.pupil_centre_px[0])
    rms = float(np.sqrt(np.mean(np.sum(np.array(errors) ** 2, axis=1))))
    message = f"half-closed lids (blink 0.3): pupil RMS {rms:.3f} px over {len(errors)}; failures {dict(failures)}"
    print(message)
    assert len(errors) >= 60 and rms <= TOLERANCE_PX, message
    assert set(failures) <= {"low_support", "implausible_ellipse", "glint_missing"}, message


def test_closed_eye_is_an_explained_failure():
    scene = load_scene("guestrin2006")
    eyes = published_eyes()[:1]
    features = simulate(eyes, scene, head_positions=scene.head_positions[:1])
    outline = eye_outlines(features, eyes, scene, blink=1.0)
    found = detect_eye(render_roi(outline[0, 0, 0, 4], np.random.default_rng(0)).image, 2)
    assert not found and found.failure == "no_dark_blob" and "closed" in found.detail
    assert not found.features.flags & PupilFlags.DETECTED and np.isnan(found.pupil_px).all()


def test_full_binocular_frame_gives_the_streamed_record():
    scene = load_scene("blignaut2014")
    eyes = published_eyes()[:1]
    features = simulate(eyes, scene, targets=scene.targets()[60:61])
    frame = render_full(eye_outlines(features, eyes, scene)[0, :, 0, 0], np.random.default_rng(0))
    record, found = detect_frame(frame.image, 2, 1, frame_id=7, led_xy_mm=scene.leds[:, :2])
    assert [d.failure for d in found] == [None, None]
    decoded = FeaturesRecord.from_payload(record.to_payload())
    assert decoded.frame_id == 7 and [e.eye.name for e in decoded.eyes] == ["RIGHT", "LEFT"]
    truth = frame.truth
    for k, (eye, detection) in enumerate(zip(decoded.eyes, found, strict=True)):
        np.testing.assert_allclose([eye.centre_x, eye.centre_y], truth.pupil_centre_px[k], atol=0.1)
        np.testing.assert_allclose(detection.glints_px(1), truth.glint_px[k], atol=0.1)


def test_glints_are_matched_to_leds_by_geometry():
    xy = np.array([[110.0, 240.0], [95.0, 241.0]])  # the glint at larger image x comes from the LED at larger x
    np.testing.assert_array_equal(match_leds(xy, 2, np.array([[188.5, 0.0], [-188.5, 0.0]])), [0, 1])
    np.testing.assert_array_equal(match_leds(xy, 2, np.array([[-188.5, 0.0], [188.5, 0.0]])), [1, 0])
    np.testing.assert_array_equal(match_leds(xy, 2, None), [1, 0])
    vertical = np.array([[100.0, 200.0], [100.5, 230.0]])  # the higher LED (world +y) makes the higher glint
    np.testing.assert_array_equal(match_leds(vertical, 2, np.array([[0.0, -50.0], [0.0, 50.0]])), [1, 0])


def _detected_features(features: Features, eyes, scene, rng) -> tuple[Features, Features, Counter]:
    """(exact, detected) features restricted to the samples on the sensor, and detection failures."""
    pupil, glints = np.full(features.pupil_centre_px.shape, np.nan), np.full(features.glint_px.shape, np.nan)
    failures = Counter()
    index = [tuple(i) for i in np.argwhere(features.visible)]
    for key, frame in render_features(features, eyes, scene, rng, index=index):
        found = detect_eye(frame.image, len(scene.leds), roi_xy=frame.roi_xy, led_xy_mm=scene.leds[:, :2])
        failures[found.failure] += found.failure is not None
        pupil[key], glints[key] = found.pupil_px, found.glints_px(len(scene.leds))
    meta = {k: getattr(features, k) for k in ("scene", "sides", "head_positions", "leds", "targets", "media")}
    exact = Features(**meta, arrays={**features.arrays, "pupil_valid": features.pupil_valid & features.visible})
    detected = Features(**meta, arrays={**features.arrays, "pupil_centre_px": pupil, "glint_px": glints,
                                        "pupil_valid": np.isfinite(pupil).all(-1) & features.visible,
                                        "glint_valid": np.isfinite(glints).all(-1)})
    return exact, detected, +failures


def test_guestrin_calibration_from_frames_matches_exact_features():
    from eyehil.analysis.study.experiments import guestrin

    scene = load_scene("guestrin2006")
    eyes = published_eyes()[:10]
    features = simulate(eyes, scene)
    exact, detected, failures = _detected_features(features, eyes, scene, np.random.default_rng(5))
    a, b = guestrin(exact, scene), guestrin(detected, scene)
    worst = max(np.nanmax(np.abs(a.h1 - b.h1)), np.nanmax(np.abs(a.h2 - b.h2)))
    message = (f"Guestrin, 10 eyes: max |H1, H2 from frames - exact| = {worst:.3f} deg (mean H1 {np.nanmean(a.h1):.3f} "
               f"exact, {np.nanmean(b.h1):.3f} frames); detection failures {dict(failures)}")
    print(message)
    assert not a.failures and not b.failures and worst <= 0.1, message


def test_blignaut_calibration_from_frames_matches_exact_features():
    """Every model and calibration set with at least two more targets than terms (so that the fit has
    residual degrees of freedom) agrees within 0.1 deg; fits as determined as model 8 at C9 (8 terms, 9
    targets) amplify any feature error and are reported, not tested."""
    from eyehil.analysis.study.experiments import blignaut
    from eyehil.analysis.study.published import CONFIGURATIONS, calibration_sets
    from eyehil.drivers.gaze.forms import MODELS, resolve_form

    scene = load_scene("blignaut2014")
    eyes = published_eyes()[:6]
    features = simulate(eyes, scene)
    exact, detected, failures = _detected_features(features, eyes, scene, np.random.default_rng(6))
    diff = np.abs(blignaut(exact, scene).errors - blignaut(detected, scene).errors)  # (E, model, configuration)
    terms = np.array([max(len(resolve_form(x)), len(resolve_form(y))) for _, (x, y) in sorted(MODELS.items())])
    targets = np.array([len(calibration_sets()[c]) for c in CONFIGURATIONS])
    posed = targets[None, :] >= terms[:, None] + 2
    message = (f"Blignaut, 6 eyes: max |error from frames - exact| = {np.nanmax(diff[:, posed]):.3f} deg over the "
               f"{posed.sum()} well-posed fits (mean {np.nanmean(diff[:, posed]):.4f}); nearly determined fits up to "
               f"{np.nanmax(diff[:, ~posed]):.2f} deg; detection failures {dict(failures)}")
    print(message)
    assert np.nanmax(diff[:, posed]) <= 0.1, message
