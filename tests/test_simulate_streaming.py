"""Issue 16: `eyehil simulate` in chunks on a process pool or a Dask cluster, writing each chunk's features away
as it arrives (`emulator/feature_file.py`) and folding it into the summary (`simulate.Digest`)."""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from eyehil.cli import main
from eyehil.emulator.eye.select import eyes_from_spec
from eyehil.emulator.feature_file import FeatureWriter, load_features
from eyehil.emulator.features import ARRAYS
from eyehil.emulator.forward import simulate
from eyehil.emulator.scene import load_scene
from eyehil.emulator.simulate import Digest, summary, warnings
from eyehil.parallel import iter_chunks


@pytest.fixture(scope="module")
def whole():
    """Five sampled eyes in one in-process forward run: the reference."""
    eyes, _ = eyes_from_spec("sample:5", 3)
    return eyes, simulate(eyes, load_scene("guestrin2006"), n_pupil_points=8)


def _same(a, b) -> None:
    for name in ARRAYS:
        x, y = np.asarray(a.arrays[name]), np.asarray(b.arrays[name])
        assert x.shape == y.shape and x.dtype == y.dtype, name
        assert np.array_equal(x, y, equal_nan=x.dtype != bool), name


@pytest.mark.parametrize("out_name", ["features.npz", "features"])
def test_chunked_pooled_run_writes_what_one_run_computes(tmp_path, capsys, whole, out_name) -> None:
    out = tmp_path / out_name
    assert main(["simulate", "--eyes", "sample:5", "--seed", "3", "--points", "8", "--workers", "2",
                 "--chunk-eyes", "2", "--quiet", "--out", str(out)]) == 0
    chunked = capsys.readouterr().out
    back = load_features(out)
    _same(back, whole[1])
    assert back.shape == (5, 1, 5, 9) and back.head_positions[0] == "central"
    assert not list(tmp_path.glob("*.partial")) and not list(tmp_path.glob("*.part"))
    assert main(["simulate", "--eyes", "sample:5", "--seed", "3", "--points", "8", "--workers", "1", "--quiet"]) == 0
    one = capsys.readouterr().out
    assert _untimed(chunked)[:-1] == _untimed(one)  # the same summary, and the line saying where it was written
    assert str(out) in chunked.splitlines()[-1]


def _untimed(text: str) -> list[str]:
    return [line for line in text.splitlines() if "fixations/s" not in line]


def test_digests_of_chunks_add_up_to_the_digest_of_the_whole(whole) -> None:
    eyes, features = whole
    scene = load_scene("guestrin2006")
    parts = [simulate(eyes[a:b], scene, n_pupil_points=8) for a, b in ((0, 1), (1, 4), (4, 5))]
    merged = Digest.of(parts[0]) + Digest.of(parts[1]) + Digest.of(parts[2])
    one = Digest.of(features)
    assert summary(merged, "x", 1.0) == summary(one, "x", 1.0)
    assert merged.counts == one.counts and merged.ranges == one.ranges
    assert all(np.array_equal(merged.cells[k], one.cells[k]) for k in one.cells)
    far = replace(scene, head_positions=(replace(scene.head_positions[0], z=2000.0), *scene.head_positions[1:]))
    lost = Digest.of(simulate(eyes[:2], far, n_pupil_points=8))
    assert "no valid fixation of 36 (the fixation solve failed for 36" in warnings(lost + lost)[0]  # 2 x 2 eyes x 9


def test_chunks_written_in_any_order_and_nothing_left_by_a_failed_run(tmp_path, whole) -> None:
    eyes, features = whole
    scene = load_scene("guestrin2006")
    parts = {a: simulate(eyes[a:a + 2], scene, n_pupil_points=8) for a in (0, 2, 4)}
    with FeatureWriter(tmp_path / "f", 5) as out:
        for a in (4, 0, 2):
            out.write(a, parts[a])
    _same(load_features(tmp_path / "f"), features)

    with pytest.raises(RuntimeError, match="1 eye"), FeatureWriter(tmp_path / "g.npz", 5) as out:
        out.write(0, parts[0])
        out.write(2, parts[2])  # eye 4 never written
    with pytest.raises(ValueError, match="outside"), FeatureWriter(tmp_path / "h", 5) as out:
        out.write(4, parts[2])  # eyes 4..5 of 5
    with pytest.raises(KeyboardInterrupt), FeatureWriter(tmp_path / "i", 5) as out:
        out.write(0, parts[0])
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_the_writer_keeps_no_chunk_in_memory(tmp_path, whole) -> None:
    """40 chunks of about 1 MB each: the writer's peak allocation stays below two chunks."""
    _, features = whole
    big = replace(features, arrays={k: np.repeat(v, 20, axis=0) for k, v in features.arrays.items()})
    chunk_bytes = sum(v.nbytes for v in big.arrays.values())
    assert chunk_bytes > 500_000
    tracemalloc.start()
    try:
        with FeatureWriter(tmp_path / "f.npz", 40 * big.shape[0]) as out:
            for i in range(40):
                out.write(i * big.shape[0], big)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * chunk_bytes, (peak, chunk_bytes)
    assert load_features(tmp_path / "f.npz").shape[0] == 40 * big.shape[0]


def test_dask_cluster_runs_the_same_chunks(whole) -> None:
    distributed = pytest.importorskip("distributed", reason="the optional 'dask' extra is not installed")
    eyes, features = whole
    chunks = [eyes[a:a + 2] for a in (0, 2, 4)]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        got = dict(iter_chunks(simulate, chunks, sizes=[2, 2, 1], scheduler=cluster.scheduler_address,
                               scene=load_scene("guestrin2006"), n_pupil_points=8))
    assert sorted(got) == [0, 1, 2]
    for i, a in enumerate((0, 2, 4)):
        part = got[i]
        assert np.array_equal(part.pupil_centre_px, features.pupil_centre_px[a:a + 2], equal_nan=True)
        assert np.array_equal(part.glint_px, features.glint_px[a:a + 2], equal_nan=True)


def test_bad_chunking_is_refused(capsys) -> None:
    assert main(["simulate", "--eyes", "sample:2", "--chunk-eyes", "0", "--quiet"]) == 2
    assert "--chunk-eyes must be >= 1" in capsys.readouterr().err


def test_an_existing_target_is_replaced_only_if_it_is_an_earlier_output(tmp_path, capsys, whole) -> None:
    """`--out ~` must not delete a home folder: a folder that is not an earlier output is refused before any
    work and left as it was; an earlier output folder (or an .npz file) is replaced."""
    _, features = whole
    precious = tmp_path / "documents"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work")
    with pytest.raises(FileExistsError, match="not an earlier eyehil features output"):
        FeatureWriter(precious, 5)
    assert main(["simulate", "--eyes", "sample:2", "--points", "8", "--quiet", "--out", str(precious)]) == 1
    assert "not an earlier eyehil features output" in capsys.readouterr().err
    assert (precious / "thesis.tex").read_text() == "years of work" and len(list(precious.iterdir())) == 1
    for target in (tmp_path / "earlier", tmp_path / "earlier.npz"):
        for _ in range(2):  # the second run replaces the first
            with FeatureWriter(target, 5) as out:
                out.write(0, features)
            _same(load_features(target), features)
