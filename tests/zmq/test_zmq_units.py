"""The facade's pieces without sockets: coordinate conversions, Pupil time, eye windows and datums, the
calibration session's pairing by time, the gazers, image encodings and the Capture state machine."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.camera import Camera, Selection
from eyehil.emulator.device.clock import FastClock
from eyehil.emulator.device.pupil.calibration import MAX_TARGETS, Session, fit, norm_to_screen, screen_to_norm
from eyehil.emulator.device.pupil.capture import Capture
from eyehil.emulator.device.pupil.datums import EyeWindow, PupilTime, exposure_datums, eye_windows
from eyehil.emulator.device.pupil.eye3d import EyeModel3d, pupil_3d_datums
from eyehil.emulator.device.pupil.frames import encode_image
from eyehil.emulator.scene import load_scene
from eyehil.protocols.enums import Eye
from eyehil.protocols.pupil import PupilMessageError, pack

GUESTRIN_SCREEN = (377.0, 301.0)


def test_screen_conversions_known_answer() -> None:
    assert norm_to_screen(GUESTRIN_SCREEN, np.array([0.0, 1.0])) == pytest.approx([188.5, 150.5])
    assert norm_to_screen(GUESTRIN_SCREEN, np.array([0.5, 0.5])) == pytest.approx([0.0, 0.0])
    xy = np.random.default_rng(1).uniform(-150, 150, (10, 2))
    np.testing.assert_allclose(norm_to_screen(GUESTRIN_SCREEN, screen_to_norm(GUESTRIN_SCREEN, xy)), xy)


def test_pupil_time_follows_time_sync() -> None:
    clock = FastClock()
    t = PupilTime(clock)
    clock.push(5_000_000)
    t.set_now(100.0)
    assert t.now() == pytest.approx(100.0, abs=1e-3)
    assert t.of_us(6_000_000) == pytest.approx(101.0) and t.to_us(101.0) == 6_000_000


@pytest.fixture(scope="module")
def subject():
    s = build_subject(DeviceOptions(scene="guestrin2006", eyes="published", eye=17))
    yield s
    s.close()


def test_datums_are_in_the_eye_image(subject) -> None:
    windows = eye_windows(subject.solver, (0,), (320, 240))
    camera = Camera(subject, (640, 480), (Eye.RIGHT,))
    camera.start(0, 250, Selection((Eye.RIGHT,), 2))
    exp = camera.take(3)
    pupil, glint = exposure_datums(exp, windows, PupilTime(FastClock()))[1]
    sensor_xy = exp.batch.centre[1, 0]
    assert pupil["ellipse"]["center"] == pytest.approx(sensor_xy - windows[0].origin)
    x, y = pupil["ellipse"]["center"]
    assert pupil["norm_pos"] == pytest.approx([x / 320, 1 - y / 240])
    assert pupil["timestamp"] == pytest.approx(exp.time_us[1] / 1e6)
    assert glint["glints"] == pupil["glints"] and glint["topic"] == "glint.0"
    full = eye_windows(subject.solver, (0,), None)
    assert full == [EyeWindow(0, 0, 0, 640, 480)]


def test_datums_built_unchecked_pass_the_key_check(subject) -> None:
    """The facade packs its exposure datums without walking their keys (`pack(check_keys=False)`): every one of
    them must pass that walk, and the walk must still refuse a non-string key."""
    windows = eye_windows(subject.solver, (0,), (320, 240))
    camera = Camera(subject, (640, 480), (Eye.RIGHT,))
    camera.start(0, 250, Selection((Eye.RIGHT,), 2))
    exp = camera.take(5)
    datums_2d = exposure_datums(exp, windows, PupilTime(FastClock()))
    found = np.array([[d["confidence"] > 0 for d in datums[0::2]] for datums in datums_2d])
    assert found.all()
    datums_3d = pupil_3d_datums(exp.batch.centre, found, EyeModel3d.of(subject.solver), windows,
                                [datums[0::2] for datums in datums_2d])
    built = [d for datums in datums_2d + datums_3d for d in datums]
    assert {d["topic"] for d in built} == {"pupil.0.2d", "glint.0", "pupil.0.3d"}
    for d in built:
        assert pack(d) == pack(d, check_keys=False)
    with pytest.raises(PupilMessageError, match="not a string"):
        pack({"topic": "pupil.0.3d", "sphere": {"center": [0.0], 1: 2}})


def _session_with_targets(subject, targets_mm: np.ndarray, settle_s: float = 0.1) -> Session:
    """A session whose samples are the exact features of each target for 0.5 s at 100 Hz, preceded by 0.1 s
    of samples looking elsewhere (which the settling time must exclude)."""
    session = Session(settle_s)
    values = subject.solver.exact(targets_mm)  # (T, E, C)
    wrong = subject.solver.exact(np.zeros((1, 2)))[0]
    for i, xy in enumerate(targets_mm):
        onset = float(i)
        session.add_ref((float(xy[0]), float(xy[1])), onset)
        session.add_ref((float(xy[0]), float(xy[1])), onset + 0.5)
        t = onset + np.arange(60) / 100
        v = np.where((t < onset + 0.1)[:, None, None], wrong, values[i])
        glints = v[..., 5:9].reshape(len(t), -1, 2, 2)
        session.add_samples(t, v[..., 0:2], glints, np.ones((len(t), 1), bool))
    return session


def test_session_pairs_samples_by_time_and_guestrin_fits(subject) -> None:
    scene = subject.solver.scene
    targets = np.array([[x, y] for y in (100.0, 0.0, -100.0) for x in (-150.0, 0.0, 150.0)])
    fixations = _session_with_targets(subject, targets).fixations(stop_s=100.0)
    np.testing.assert_allclose(fixations.targets_mm, targets)
    np.testing.assert_allclose(fixations.pupil[:, 0], subject.solver.exact(targets)[:, 0, 0:2])
    gazer = fit(fixations, scene, (0,))
    assert gazer.class_name == "GazerGuestrin" and gazer.n_targets == 9
    gaze, used = gazer.map(fixations.pupil, fixations.glints, fixations.valid)
    assert used.all() and np.abs(gaze - targets).max() < 10.0  # mm: the model eye is not the estimator's
    assert gazer.params["eyes"]["0"]["fitted"] == ["R", "K", "alpha_deg", "beta_deg"]


def test_fit_failures_are_reasons(subject) -> None:
    scene = subject.solver.scene
    empty = Session(0.1).fixations(1.0)
    assert "no calibration target" in fit(empty, scene, (0,))
    one_led = load_scene("blignaut2014")
    assert "one LED and one eye" in fit(empty, one_led, (0,))


def test_image_encodings() -> None:
    image = np.random.default_rng(0).integers(0, 255, (24, 32), dtype=np.uint8)
    assert encode_image(image, "gray") == image.tobytes()
    bgr = np.frombuffer(encode_image(image, "bgr"), np.uint8).reshape(24, 32, 3)
    assert (bgr == image[..., None]).all()
    decoded = cv2.imdecode(np.frombuffer(encode_image(image, "jpeg"), np.uint8), cv2.IMREAD_UNCHANGED)
    assert decoded.shape == (24, 32)


def test_capture_reacts_to_notifications(tmp_path) -> None:
    shown = []
    capture = Capture(load_scene("guestrin2006"), (0,), PupilTime(FastClock()), lambda xy, t: shown.append(xy),
                      record_dir=tmp_path)
    try:
        assert capture.on_message("notify.frame_publishing.set_format", {"subject": "frame_publishing.set_format",
                                                                         "format": "png"}) == []
        out = capture.on_message("notify.start_plugin", {"subject": "start_plugin", "name": "Frame_Publisher",
                                                         "args": {"format": "jpeg"}})
        assert out[0]["subject"] == "frame_publishing.started" and capture.frame_format == "jpeg"
        capture.on_message("notify.eyehil.stimulus", {"subject": "eyehil.stimulus", "norm_pos": [0.0, 1.0]})
        assert shown == [(188.5, 150.5)]
        out = capture.on_message("notify.recording.should_start", {"subject": "recording.should_start",
                                                                   "session_name": "../../etc"})
        assert out[0]["session_name"] == "_.._etc" and (tmp_path / "_.._etc").is_dir()
        assert capture.on_message("notify.unknown", {"subject": "unknown"}) == []
        assert capture.on_message("pupil.0.2d", {"topic": "pupil.0.2d"}) == []
        assert capture.counters["frame_formats_refused"] == 1
    finally:
        capture.close()


def test_a_pupil_off_its_window_has_no_confidence(subject) -> None:
    camera = Camera(subject, (640, 480), (Eye.RIGHT,))
    camera.start(0, 250, Selection((Eye.RIGHT,), 2))
    exp = camera.take(1)
    far = [EyeWindow(0, 500, 400, 100, 50)]
    pupil = exposure_datums(exp, far, PupilTime(FastClock()))[0][0]
    assert pupil["confidence"] == 0.0 and pupil["ellipse"]["center"] == [0.0, 0.0] and pupil["diameter"] == 0.0
    assert far[0].contains(np.array([500.0, 400.0])) and not far[0].contains(np.array([600.0, 400.0]))


def test_targets_are_capped() -> None:
    shown = []
    capture = Capture(load_scene("guestrin2006"), (0,), PupilTime(FastClock()), lambda xy, t: shown.append(xy))
    ref = [{"norm_pos": [i / 400, 0.5], "timestamp": float(i)} for i in range(300)]
    capture.on_message("notify.calibration.add_ref_data", {"subject": "calibration.add_ref_data", "ref_data": ref})
    assert len(shown) == MAX_TARGETS and capture.counters["targets_refused"] == 300 - MAX_TARGETS
    capture.on_message("notify.calibration.should_start", {"subject": "calibration.should_start"})
    capture.on_message("notify.calibration.add_ref_data", {"subject": "calibration.add_ref_data", "ref_data": ref})
    assert len(capture.session.targets) == MAX_TARGETS
    capture.close()
