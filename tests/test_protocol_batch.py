"""Vectorised FEATURES codec against the per-message codec, and camera images as FRAME_CHUNKs (split, encoded a run at
a time, reassembled)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eyehil.protocols import CrcError, Eye, FrameChunk, MalformedPayloadError, cobs, decode_wire, encode, kernels
from eyehil.protocols.batch import FeaturesBatch, decode_features_batch, encode_features_batch, features_dtype
from eyehil.protocols.errors import BadLengthError
from eyehil.protocols.images import MAX_CHUNK_DATA, ImageAssembler, ImageChunks, split_image
from eyehil.protocols.samples import EyeFeatures, Features, Glint


def _batch(rng: np.random.Generator, n: int, n_eyes: int, n_glints: int) -> FeaturesBatch:
    f32 = lambda *shape: rng.normal(300, 80, shape).astype(np.float32)  # noqa: E731
    u8 = lambda *shape: rng.integers(0, 256, shape, dtype=np.uint8)  # noqa: E731
    return FeaturesBatch(
        frame_id=rng.integers(0, 2**32, n, dtype=np.uint32), eye=np.arange(n_eyes, dtype=np.uint8),
        flags=u8(n, n_eyes), centre=f32(n, n_eyes, 2), axes=f32(n, n_eyes, 2), angle_deg=f32(n, n_eyes),
        confidence=rng.random((n, n_eyes), dtype=np.float32), glint_led=u8(n, n_eyes, n_glints),
        glint_xy=f32(n, n_eyes, n_glints, 2), glint_flags=u8(n, n_eyes, n_glints),
    )  # fmt: skip


def _message(b: FeaturesBatch, i: int) -> Features:
    """Sample `i` of a batch as a `Features` message, built field by field."""
    eyes = []
    for e, eye_id in enumerate(b.eye):
        glints = tuple(
            Glint(int(b.glint_led[i, e, g]), float(b.glint_xy[i, e, g, 0]), float(b.glint_xy[i, e, g, 1]),
                  int(b.glint_flags[i, e, g]))
            for g in range(b.glint_led.shape[-1])
        )  # fmt: skip
        pupil = [*b.centre[i, e], *b.axes[i, e], b.angle_deg[i, e], b.confidence[i, e]]
        eyes.append(EyeFeatures(int(eye_id), int(b.flags[i, e]), *map(float, pupil), glints))
    return Features(int(b.frame_id[i]), tuple(eyes))


def test_dtype_sizes_match_the_specification() -> None:
    assert features_dtype(1, 2).itemsize == 72
    assert features_dtype(2, 2).itemsize == 119
    assert features_dtype(1, 0).itemsize == 52


@pytest.mark.parametrize(("n_eyes", "n_glints"), [(1, 2), (2, 2), (2, 0), (1, 5)])
def test_batch_encoding_equals_message_encoding(n_eyes: int, n_glints: int) -> None:
    rng = np.random.default_rng(9)
    batch = _batch(rng, 50, n_eyes, n_glints)
    stamps = rng.integers(0, 2**62, 50, dtype=np.uint64)
    wires = encode_features_batch(batch, 2**32 - 3, stamps)
    for i, wire in enumerate(wires):
        assert wire == encode(_message(batch, i), (2**32 - 3 + i) % 2**32, int(stamps[i]))
        assert decode_wire(wire)[1] == _message(batch, i)


def test_batch_decoding_inverts_encoding() -> None:
    rng = np.random.default_rng(10)
    batch = _batch(rng, 20, 2, 2)
    raws = [cobs.decode(w[:-1]) for w in encode_features_batch(batch, 0, np.zeros(20, np.uint64))]
    back = decode_features_batch(raws, 2, 2)
    for name in FeaturesBatch.__dataclass_fields__:
        assert np.array_equal(getattr(back, name), getattr(batch, name)), name


def test_batch_decoding_refuses_other_frames() -> None:
    rng = np.random.default_rng(11)
    raws = [cobs.decode(w[:-1]) for w in encode_features_batch(_batch(rng, 3, 1, 2), 0, np.zeros(3, np.uint64))]
    with pytest.raises(BadLengthError):
        decode_features_batch(raws, 2, 2)
    corrupted = [raws[0], raws[1][:30] + bytes([raws[1][30] ^ 1]) + raws[1][31:], raws[2]]
    with pytest.raises(CrcError):
        decode_features_batch(corrupted, 1, 2)
    swapped = _batch(rng, 1, 2, 2)
    swapped = FeaturesBatch(**{**swapped.__dict__, "eye": np.array([1, 0], np.uint8)})
    mixed = [cobs.decode(w[:-1]) for b in (_batch(rng, 1, 2, 2), swapped) for w in encode_features_batch(b, 0, [0])]
    with pytest.raises(MalformedPayloadError):
        decode_features_batch(mixed, 2, 2)


@pytest.mark.parametrize("dtype", [np.uint8, np.dtype("<u2"), np.dtype(">u2")])
def test_split_and_reassemble_an_image(dtype: np.dtype) -> None:
    rng = np.random.default_rng(12)
    image = rng.integers(0, 256 if dtype == np.uint8 else 4096, (480, 640)).astype(dtype)
    chunks = split_image(42, Eye.BOTH, image, (16, 8))
    assert all(len(c.data) <= MAX_CHUNK_DATA for c in chunks)
    assembler = ImageAssembler()
    results = [assembler.add(decode_wire(encode(c, i, 0))[1]) for i, c in enumerate(chunks)]
    assert results[:-1] == [None] * (len(chunks) - 1)
    done = results[-1]
    assert np.array_equal(done.pixels, image) and (done.frame_id, done.roi_x, done.roi_y) == (42, 16, 8)


def test_assembler_drops_an_incomplete_image_when_the_next_starts() -> None:
    image = np.arange(100, dtype=np.uint8).reshape(10, 10)
    first, second = split_image(1, Eye.RIGHT, image, chunk_data=30), split_image(2, Eye.RIGHT, image, chunk_data=30)
    assembler = ImageAssembler()
    for chunk in first[:2] + second:
        done = assembler.add(chunk)
    assert done.frame_id == 2 and assembler.incomplete == 1 and assembler.complete == 1


def test_frame_chunk_must_lie_inside_its_image() -> None:
    with pytest.raises(ValueError):
        FrameChunk(1, Eye.LEFT, 1, 2, 2, 0, 0, 0, 1, 2, b"abc")


def _split_reference(frame_id: int, eye: Eye, image: np.ndarray, roi_xy: tuple[int, int], chunk_data: int) -> list:
    """The chunks of `image` cut one by one from its little-endian bytes (what `split_image` must return)."""
    raw = image.astype(image.dtype.newbyteorder("<")).tobytes()
    count = max(1, -(-len(raw) // chunk_data))
    fmt = 1 if image.dtype.itemsize == 1 else 2
    return [FrameChunk(frame_id, eye, fmt, image.shape[1], image.shape[0], *roi_xy, k, count, k * chunk_data,
                       raw[k * chunk_data : (k + 1) * chunk_data]) for k in range(count)]  # fmt: skip


@pytest.mark.parametrize("dtype", [np.uint8, np.dtype("<u2"), np.dtype(">u2")])
def test_split_image_matches_the_chunk_by_chunk_reference(dtype: np.dtype) -> None:
    rng = np.random.default_rng(13)
    cases = [((240, 320), MAX_CHUNK_DATA), ((1, 1), MAX_CHUNK_DATA), ((0, 5), MAX_CHUNK_DATA), ((7, 582), 4074),
             ((7, 582), 582), ((97, 42), 4073), ((240, 320), 1000), ((3, 5), 1), ((9, 11), 7), ((50, 2), 100)]
    for shape, chunk_data in cases:  # 7 x 582 = 4074 bytes: one full chunk in MONO8, two in MONO16
        image = rng.integers(0, 256 if dtype == np.uint8 else 65536, shape).astype(dtype)
        chunks = split_image(9, Eye.LEFT, image, (3, 4), chunk_data)
        assert chunks == _split_reference(9, Eye.LEFT, image, (3, 4), chunk_data)
        assert all(type(c.data) is bytes and c.eye is Eye.LEFT for c in chunks)
        assert b"".join(c.data for c in chunks) == image.astype(image.dtype.newbyteorder("<")).tobytes()


def test_assembler_drops_an_image_whose_chunks_disagree_on_its_geometry() -> None:
    image = np.arange(100, dtype=np.uint8).reshape(10, 10)
    first, *rest = split_image(1, Eye.RIGHT, image, chunk_data=30)
    changes = (("width", 20), ("height", 11), ("roi_x", 1), ("roi_y", 1), ("chunk_count", 5), ("pixel_format", 2))
    for field, value in changes:
        assembler = ImageAssembler()
        assert assembler.add(first) is None
        assert assembler.add(replace(rest[0], **{field: value})) is None and assembler.inconsistent == 1, field
        assert [assembler.add(c) for c in rest] == [None] * len(rest)  # the image restarts without its first chunk
    assembler = ImageAssembler()
    assert [assembler.add(c) for c in (first, *rest)][-1].pixels.tobytes() == image.tobytes()
    assert assembler.inconsistent == 0 and assembler.complete == 1


KERNEL_PATHS = [pytest.param(True, id="compiled", marks=pytest.mark.skipif(
                    not kernels.AVAILABLE, reason=f"compiled kernels unavailable: {kernels.REASON}")),
                pytest.param(False, id="python")]


def _wire_in_runs(chunks: ImageChunks, seq: int, timestamp_us: int, rooms) -> tuple[list[bytes], list[int]]:
    """An image's wire bytes taken in runs of the given rooms (the last one repeated until the image is done)."""
    runs, counts, k = [], [], 0
    while not chunks.done:
        data, n = chunks.wire(seq + sum(counts), timestamp_us, rooms[min(k, len(rooms) - 1)])
        runs.append(data)
        counts.append(n)
        k += 1
    return runs, counts


@pytest.mark.parametrize("compiled", KERNEL_PATHS)
@settings(max_examples=60, deadline=None)
@given(shape=st.tuples(st.integers(1, 60), st.integers(1, 90)), wide=st.booleans(), chunk_data=st.integers(1, 4074),
       seq=st.integers(0, 2**32 - 1), timestamp=st.integers(0, 2**64 - 1),
       rooms=st.lists(st.integers(1, 20_000), min_size=1, max_size=5), zeros=st.floats(0.0, 1.0),
       roi=st.tuples(st.integers(0, 65535), st.integers(0, 65535)))
def test_image_chunks_are_the_split_chunks_encoded_property(compiled: bool, shape, wide: bool, chunk_data: int,
                                                            seq: int, timestamp: int, rooms, zeros: float,
                                                            roi) -> None:
    """A run of chunks from `ImageChunks.wire` is byte for byte `encode` of the `split_image` chunks, numbered on
    from `seq` (wrapping at 2^32), in whatever runs the room allows: each run stops once it holds `room` bytes or
    more; the compiled kernel and the Python path alike."""
    rng = np.random.default_rng(abs(hash((shape, chunk_data, seq))) % 2**32)
    image = rng.integers(0, 65536 if wide else 256, shape).astype("<u2" if wide else np.uint8)
    image[rng.random(shape) < zeros] = 0  # runs of zeros exercise COBS
    reference = [encode(c, (seq + k) % 2**32, timestamp)
                 for k, c in enumerate(split_image(7, Eye.LEFT, image, roi, chunk_data))]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(kernels, "AVAILABLE", compiled)
        chunks = ImageChunks(7, Eye.LEFT, image, roi, chunk_data)
        runs, counts = _wire_in_runs(chunks, seq, timestamp, rooms)
    assert b"".join(runs) == b"".join(reference) and sum(counts) == chunks.count == len(reference)
    done = 0
    for k, (data, n) in enumerate(zip(runs, counts, strict=True)):
        room = rooms[min(k, len(rooms) - 1)]
        assert n >= 1 and data == b"".join(reference[done:done + n])
        assert len(data) - len(reference[done + n - 1]) < room  # the run's last chunk started under the room
        assert done + n == len(reference) or len(data) >= room  # it stopped only when full, or at the image's end
        done += n


@pytest.mark.parametrize("compiled", KERNEL_PATHS)
def test_image_chunks_send_nothing_without_room_and_refuse_what_split_image_refuses(compiled: bool,
                                                                                   monkeypatch) -> None:
    monkeypatch.setattr(kernels, "AVAILABLE", compiled)
    image = np.arange(240 * 320, dtype=np.uint32).astype(np.uint8).reshape(240, 320)
    chunks = ImageChunks(3, Eye.RIGHT, image, (0, 0))
    assert chunks.wire(0, 0, 0) == (b"", 0) and chunks.wire(0, 0, -5) == (b"", 0) and chunks.sent == 0
    data, n = chunks.wire(0, 0, 10**9)
    assert n == chunks.count == 19 and chunks.done and chunks.wire(19, 0, 10**9) == (b"", 0)
    assert [decode_wire(f + b"\x00")[0].seq for f in data.split(b"\x00")[:-1]] == list(range(19))
    for empty in (np.zeros((0, 5), np.uint8), np.zeros((3, 0), "<u2")):  # one chunk without pixels, as split_image
        reference = encode(split_image(4, Eye.LEFT, empty)[0], 9, 1)
        assert ImageChunks(4, Eye.LEFT, empty).wire(9, 1, 1) == (reference, 1)
    for bad in (np.zeros((2, 2, 2), np.uint8), np.zeros((2, 2), np.float32)):
        with pytest.raises(ValueError):
            ImageChunks(1, Eye.RIGHT, bad)
    with pytest.raises(ValueError):
        ImageChunks(1, Eye.RIGHT, image, chunk_data=MAX_CHUNK_DATA + 1)
    with pytest.raises(ValueError):
        ImageChunks(1, Eye.RIGHT, image, roi_xy=(70_000, 0))
    for timestamp in (-1, 1 << 64):  # what the header cannot carry, on either path
        with pytest.raises(ValueError, match="out of range"):
            ImageChunks(1, Eye.RIGHT, image).wire(0, timestamp, 10)
