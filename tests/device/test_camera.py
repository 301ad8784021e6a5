"""The camera's exposure schedule: prepared in blocks, taken, skipped and invalidated in any pieces, the same
exposures as taken at once."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from eyehil.emulator.device.build import DeviceOptions, build_subject
from eyehil.emulator.device.camera import PREPARE_S, Camera, Exposures, Selection
from eyehil.protocols.enums import Eye

RATE_HZ = 100


def _camera() -> Camera:
    subject = build_subject(DeviceOptions(script="demo", clock="fast", seed=3), appearance=False)
    camera = Camera(subject, (640, 480), (Eye.RIGHT,))
    camera.start(0, RATE_HZ, Selection((Eye.RIGHT,), 2))
    return camera


def _rows(e: Exposures) -> dict[str, np.ndarray]:
    rows = {f.name: getattr(e.batch, f.name) for f in fields(e.batch) if f.name != "eye"}
    return rows | {"time_us": e.time_us, "values": e.values, "blink": e.blink}


def _join(parts: list[Exposures]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([_rows(p)[k] for p in parts]) for k in _rows(parts[0])}


def test_exposures_taken_in_pieces_and_skipped_are_those_taken_at_once() -> None:
    whole = _rows(_camera().take(120))
    camera, parts, taken, k = _camera(), [], [], 0
    pieces = [1, 1, 3, 7, 2, 1, 1, 11, 4, 1] * 3  # across the prepared blocks' edges (PREPARE_S of exposures each)
    skips = {5: 2, 9: 6, 17: 1}
    for i, n in enumerate(pieces):
        if i in skips:
            camera.skip(skips[i])
            k += skips[i]
        parts.append(camera.take(n))
        assert [int(f) for f in parts[-1].batch.frame_id] == list(range(k, k + n))
        taken += range(k, k + n)
        k += n
    assert camera.taken == k and k <= 120 and round(RATE_HZ * PREPARE_S) > 1
    got = _join(parts)
    assert np.array_equal(got["frame_id"], whole["frame_id"][taken])
    for key in got:
        np.testing.assert_array_equal(got[key], whole[key][taken], err_msg=key)


def test_invalidate_forgets_the_prepared_exposures_from_a_time_on() -> None:
    camera = _camera()
    first = camera.take(2)
    camera.invalidate(int(first.time_us[-1]) + 1)  # the prepared exposures after the second are observed again
    again = camera.take(3)
    reference = _camera().take(5)
    np.testing.assert_array_equal(again.time_us, reference.time_us[2:])
    np.testing.assert_array_equal(again.values, reference.values[2:])
    camera.skip(10**6)  # more than prepared: nothing is left, the schedule moves on
    assert int(camera.take(1).batch.frame_id[0]) == 5 + 10**6


def test_prepared_until_is_the_last_prepared_exposure_and_a_view_blink_starts_after_it() -> None:
    from eyehil.emulator.device.build import build_device
    from eyehil.emulator.device.cli import ViewBlink

    camera = _camera()
    assert camera.prepared_until_us == camera.time_of(-1)  # nothing prepared yet
    taken = camera.take(1)
    assert camera.prepared_until_us == camera.time_of(round(RATE_HZ * PREPARE_S) - 1) > int(taken.time_us[-1])
    camera.skip(10**3)
    assert camera.prepared_until_us == camera.time_of(camera.taken - 1)
    core = build_device(DeviceOptions(clock="fast", rate_hz=RATE_HZ))
    try:
        core.camera.start(0, RATE_HZ, Selection((Eye.RIGHT,), 2))
        core.camera.take(1)  # a fast clock prepares FAST_PREPARE_S (and FAST_PREPARE_MIN exposures) ahead, beyond
        # the view's own lead
        horizon = core.camera.prepared_until_us
        assert horizon > core.clock.now_us() + ViewBlink.LEAD_US
        assert ViewBlink(core).blink(0.2)
        times = np.arange(0, horizon + 400_000, 1000)
        closed = times[core.subject.observe(times).blink]
        assert len(closed) and closed[0] > horizon  # what the camera had prepared stays open-eyed
    finally:
        core.close()


def test_a_fast_clock_prepares_blocks_of_at_least_its_minimum_of_exposures() -> None:
    from eyehil.emulator.device.build import build_device
    from eyehil.emulator.device.camera import FAST_PREPARE_MIN, FAST_PREPARE_S

    for rate in (100, 1000):
        core = build_device(DeviceOptions(clock="fast", rate_hz=rate))
        try:
            core.camera.start(0, rate, Selection((Eye.RIGHT,), 2))
            core.camera.take(1)
            block = max(FAST_PREPARE_MIN, round(rate * FAST_PREPARE_S))
            assert core.camera.prepared_until_us == core.camera.time_of(block - 1)
        finally:
            core.close()
