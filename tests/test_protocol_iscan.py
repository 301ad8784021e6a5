"""ISCAN-compatible legacy mode: words on the wire, commands, and a parser that resynchronises."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from eyehil.protocols.iscan import (
    DEFAULT_OUTPUTS,
    HEADER_WORD,
    IscanCommand,
    IscanOutput,
    IscanParser,
    encode_sample,
    encode_samples,
    parse_commands,
    select_outputs,
    to_words,
)

GOLDEN = Path(__file__).parent / "golden" / "iscan.hex"


def test_one_record_known_answer() -> None:
    wire = encode_sample([100.0, 200.04, 0.05, 6553.5])
    assert wire == bytes.fromhex("4444 e803 d007 0000 ffff".replace(" ", ""))
    assert HEADER_WORD == 0x4444 and len(wire) == 10


def test_words_round_clip_and_blank() -> None:
    words = to_words(np.array([1.26, 1.24, -3.0, 7000.0, np.nan, 0.15, 0.25]))
    assert words.tolist() == [13, 12, 0, 65535, 0, 2, 2]  # ties to even: 1.5 -> 2, 2.5 -> 2
    assert words.dtype == np.dtype("<u2")


def test_golden_vector() -> None:
    lines = GOLDEN.read_text(encoding="utf-8").splitlines()
    golden = bytes.fromhex(" ".join(ln for ln in lines if not ln.startswith("#")))
    values = np.array([[312.25, 241.5, 305.125, 250.0], [np.nan, np.nan, 0.0, 7000.0]])
    assert encode_samples(values) == golden


def test_commands() -> None:
    assert parse_commands(b"\x80\x00\x81\x7f\xff\x80") == [IscanCommand.START, IscanCommand.STOP, IscanCommand.START]
    assert parse_commands(b"hello") == []


def test_select_outputs_in_configured_order() -> None:
    pupil, cr = np.array([[1.0, 2.0]]), np.array([[3.0, 4.0]])
    assert select_outputs(pupil, cr).tolist() == [[1.0, 2.0, 3.0, 4.0]]
    assert select_outputs(pupil, cr, [IscanOutput.CR_V, IscanOutput.PUPIL_H]).tolist() == [[4.0, 1.0]]


def _values(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """Pixel values that survive the x10 quantisation exactly, below the 0x4444 data word."""
    return rng.integers(0, 15000, (n, k)) / 10.0


@pytest.mark.parametrize("k", [1, 2, 4])
def test_parser_reads_a_stream_split_anywhere(k: int) -> None:
    rng = np.random.default_rng(13)
    values = _values(rng, 300, k)
    stream = b"\x44\x13\x99" + encode_samples(values)  # garbage, including half a header, first
    parser = IscanParser(k)
    cuts = sorted(rng.integers(0, len(stream), 120).tolist())
    out = [parser.feed(stream[a:b]) for a, b in itertools.pairwise([0, *cuts, len(stream)])]
    got = np.concatenate(out)
    assert np.array_equal(got, values[: len(got)]) and len(got) >= 299  # the last waits for confirmation only
    assert parser.samples == len(got) and parser.bytes_discarded == 3


def _damaged_stream() -> tuple[np.ndarray, bytes]:
    """100 records of which record 20 (bytes 200..209) lost 3 bytes."""
    values = _values(np.random.default_rng(14), 100, len(DEFAULT_OUTPUTS))
    stream = bytearray(encode_samples(values))
    del stream[205:208]
    return values, bytes(stream)


def test_parser_resynchronises_after_byte_loss() -> None:
    values, stream = _damaged_stream()
    parser = IscanParser()
    got = parser.feed(stream)
    assert parser.resyncs == 1 and len(got) == 99
    assert np.array_equal(got[:20], values[:20])  # got[20] is record 20 damaged: no checksum to tell
    assert np.array_equal(got[21:], values[22:])  # record 21 lost its header to the damaged one


def test_confirming_parser_drops_the_damaged_record() -> None:
    values, stream = _damaged_stream()
    parser = IscanParser(confirm=True)
    got = np.concatenate([parser.feed(stream[:500]), parser.feed(stream[500:])])
    assert parser.resyncs == 1 and parser.dropped == 1
    assert np.array_equal(got, np.concatenate([values[:20], values[21:-1]]))  # the last awaits its successor


def test_parser_never_raises_on_random_bytes() -> None:
    rng = np.random.default_rng(15)
    parser = IscanParser()
    for _ in range(200):
        out = parser.feed(rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8).tobytes())
        assert out.shape[1] == 4
        assert len(parser._buf) <= 2 * parser.stride + 2
    values = _values(rng, 5, 4)
    got = parser.feed(encode_samples(values) + encode_samples(values))
    assert np.array_equal(got[-5:], values)
