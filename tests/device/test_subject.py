"""The simulated subject: STIMULUS coordinates, gaze scripts, exact and interpolated features, blinks."""

from __future__ import annotations

import numpy as np
import pytest

from eyehil.drivers.calibration import screen_to_stimulus as host_to_stimulus
from eyehil.drivers.gaze.geometry import Screen as HostScreen
from eyehil.emulator.device.gaze import Blink, Fixation, Kind, Pursuit, Saccade, Timeline, plan, saccade_duration_s
from eyehil.emulator.device.solver import FeatureSolver, ellipse_from_moments, ellipse_to_moments
from eyehil.emulator.device.stimulus import screen_to_stimulus, stimulus_to_screen
from eyehil.emulator.device.subject import Behaviour, Subject
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene


@pytest.fixture(scope="module")
def solver() -> FeatureSolver:
    return FeatureSolver(normative_eye("navarro"), load_scene("guestrin2006"))


def test_stimulus_coordinates_known_answers() -> None:
    screen = load_scene("guestrin2006").screen  # 377 x 301 mm
    assert stimulus_to_screen(screen, 0.0, 0.0) == (188.5, 150.5)  # top-left: subject's left (+x), up
    assert stimulus_to_screen(screen, 188.5, 150.5) == (0.0, 0.0)
    assert stimulus_to_screen(screen, 377.0, 301.0) == (-188.5, -150.5)  # bottom-right: subject's right, down
    assert screen_to_stimulus(screen, *stimulus_to_screen(screen, 12.5, 250.0)) == (12.5, 250.0)


def test_host_and_device_agree_on_stimulus_coordinates() -> None:
    scene = load_scene("blignaut2014")
    host_screen = HostScreen(centre=scene.screen.centre, size_mm=scene.screen.size)
    xy = np.array([[100.0, -50.0], [-247.5, 140.0]])  # host screen mm (centre, x subject's left, y up)
    for point, stim in zip(xy, host_to_stimulus(host_screen, xy), strict=True):
        np.testing.assert_allclose(stimulus_to_screen(scene.screen, *stim), point)


def test_plan_saccade_main_sequence_and_fixation() -> None:
    centre = np.array([0.0, 0.0, 650.0])
    pieces = plan([Fixation((113.6, 0.0), 0.5)], (0.0, 0.0), 1_000, centre)  # about 10 deg
    saccade, hold = pieces
    assert saccade.kind is Kind.MOVE and hold.kind is Kind.HOLD and hold.start_us == saccade.end_us
    assert saccade.end_us - saccade.start_us == pytest.approx(saccade_duration_s(10.0) * 1e6, rel=0.01)
    assert hold.end_us - hold.start_us == 500_000


def test_timeline_profiles_and_redirect() -> None:
    centre = np.array([0.0, 0.0, 650.0])
    timeline = Timeline((0.0, 0.0))
    timeline.cut(0)
    timeline.extend(plan([Saccade((100.0, 0.0), 0.1), Pursuit((0.0, 0.0), 10.0), Blink(0.1)], (0.0, 0.0), 0, centre))
    xy, kind = timeline.evaluate(np.array([0, 50_000, 100_000]))
    np.testing.assert_allclose(xy[:, 0], [0.0, 50.0, 100.0])  # minimum jerk: halfway at half time
    assert list(kind) == [Kind.MOVE, Kind.MOVE, Kind.MOVE]
    pursuit = timeline.pieces[2]
    quarter = (pursuit.start_us * 3 + pursuit.end_us) // 4
    assert timeline.position(quarter)[0] == pytest.approx(75.0, abs=0.01)  # linear
    here = timeline.cut(50_000)  # redirect mid-saccade
    assert here == pytest.approx((50.0, 0.0))
    timeline.hold_forever((-10.0, 5.0))
    assert timeline.position(10**9) == (-10.0, 5.0)


def test_moments_round_trip() -> None:
    axes, angle = np.array([[30.0, 20.0], [10.0, 10.0]]), np.array([170.0, 0.0])
    back_axes, back_angle = ellipse_from_moments(ellipse_to_moments(axes, angle))
    np.testing.assert_allclose(back_axes, axes)
    assert back_angle[0] == pytest.approx(170.0)


def test_exact_features_are_the_forward_model(solver: FeatureSolver) -> None:
    xy = np.array([[50.0, -20.0]])
    values = solver.exact(xy)[0, 0]
    f = simulate(solver.eye, solver.scene, targets=solver.world(xy))
    np.testing.assert_allclose(values[:2], f.pupil_centre_px[0, 0, 0, 0])
    np.testing.assert_allclose(values[5:9].reshape(2, 2), f.glint_px[0, 0, 0, 0])


def test_interpolation_between_grid_points_is_close(solver: FeatureSolver) -> None:
    xy = np.array([[37.0, 11.0], [-120.0, 80.0], [150.0, -140.0]])
    diff = np.abs(solver.interpolate(xy) - solver.exact(xy))
    assert np.nanmax(diff[..., [0, 1, 5, 6, 7, 8]]) < 0.05  # px: centres and glints


def test_subject_fixates_blinks_and_jitters(solver: FeatureSolver) -> None:
    script = [Fixation((50.0, 50.0), 0.2), Blink(0.1), Fixation((50.0, 50.0), 0.2)]
    still = Subject(solver, script=script, repeat=False, start=(50.0, 50.0))
    obs = still.observe(np.arange(0, 500_000, 10_000))
    assert obs.blink.sum() == 10 and np.isnan(obs.values[obs.blink]).all()
    np.testing.assert_array_equal(obs.values[~obs.blink][0], solver.exact(np.array([[50.0, 50.0]]))[0])
    jittery = Subject(solver, Behaviour(jitter_deg=0.1), rng=np.random.default_rng(3), start=(50.0, 50.0))
    values = jittery.observe(np.arange(0, 100_000, 10_000)).values[:, 0, 0]
    assert 0.05 < values.std() < 2.0  # px: a tenth of a degree moves the pupil image a little
    still.close()
    jittery.close()


def test_a_requested_blink_closes_the_eyes_then_they_open(solver: FeatureSolver) -> None:
    subject = Subject(solver, start=(50.0, 50.0))
    assert subject.blink(200_000, 0.1)
    obs = subject.observe(np.arange(0, 500_000, 10_000))
    assert np.flatnonzero(obs.blink).tolist() == list(range(20, 30))  # 200..290 ms closed, open again at 300
    with pytest.raises(ValueError):
        subject.blink(600_000, 0.0)
    with pytest.raises(ValueError):
        subject.blink(600_000, float("nan"))
    accepted = [subject.blink(1_000_000 + k, 0.1) for k in range(200)]
    assert accepted.count(True) < 200 and not accepted[-1]  # bounded: a page cannot grow the list without end
    subject.close()
