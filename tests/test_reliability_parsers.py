"""Issue 11, finding 10 and the fuzzing deliverable: every parser raises only its package's documented error.

Hypothesis-driven, bounded for CI (`max_examples` below); the long mutation run is `python -m bench fuzz`.
Inputs that found bugs live in tests/corpus/<parser>/ and are replayed here.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench.fuzz import PARSERS, mutate, seeds
from eyehil.drivers.errors import RecordingError
from eyehil.drivers.recording import read_recording
from eyehil.emulator.scene import SceneError
from eyehil.emulator.scene.loader import scene_from_toml_bytes
from eyehil.protocols.usbip.messages import UsbipError, decode_devlist_reply

CORPUS = Path(__file__).parent / "corpus"
CI = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize("name", sorted(PARSERS))
@CI
@given(data=st.data())
def test_mutated_inputs_raise_only_the_documented_error(name: str, data) -> None:
    parser = PARSERS[name]
    seed = data.draw(st.sampled_from(seeds(name)))
    mutations = data.draw(st.lists(st.tuples(st.integers(0, 6), st.integers(0, 1 << 30), st.binary(max_size=8)),
                                   max_size=6))
    parser.run(mutate(seed, mutations))  # raises AssertionError only if something undocumented escaped


@pytest.mark.parametrize("name", sorted(PARSERS))
@CI
@given(raw=st.binary(max_size=600))
def test_random_bytes_raise_only_the_documented_error(name: str, raw: bytes) -> None:
    PARSERS[name].run(raw)


CORPUS_FILES = sorted(p for p in CORPUS.glob("*/*") if p.is_file())


@pytest.mark.parametrize("path", CORPUS_FILES, ids=[f"{p.parent.name}/{p.name}" for p in CORPUS_FILES])
def test_corpus_inputs_that_once_found_bugs(path: Path) -> None:
    PARSERS[path.parent.name].run(path.read_bytes())


# --- the findings, spelled out ---------------------------------------------------------------------------------------
def _recording(tmp_path: Path, *lines: object) -> Path:
    header = {"format": "eyehil-recording", "version": 1}
    path = tmp_path / "r.jsonl"
    path.write_bytes(b"\n".join(x if isinstance(x, bytes) else json.dumps(x).encode() for x in (header, *lines))
                     + b"\n")
    return path


@pytest.mark.parametrize("line", [
    {"type": "sample"},  # KeyError before
    {"type": "sample", "seq": "x", "frame_id": 0, "device_us": 0, "host_us": 0, "lost_before": 0,
     "skipped_before": 0, "target_id": None, "eyes": []},  # ValueError
    {"type": "sample", "seq": 10**30, "frame_id": 0, "device_us": 0, "host_us": 0, "lost_before": 0,
     "skipped_before": 0, "target_id": None, "eyes": []},  # OverflowError
    {"type": "sample", "seq": 1, "frame_id": 0, "device_us": 0, "host_us": 0, "lost_before": 0,
     "skipped_before": 0, "target_id": None, "eyes": [7]},  # TypeError
    [1, 2], {"type": ["a"]}, b"\xff\xfe{}",
])
def test_recording_reader_raises_only_recording_error(tmp_path: Path, line) -> None:
    with pytest.raises(RecordingError):
        read_recording(_recording(tmp_path, line, {"type": "end"}))


@pytest.mark.parametrize("raw", [b"\xff = 1", b"camera = 3", b"[[head_positions]]\n[head_positions.x]\n",
                                 b"extra = 5", b"[[leds]]\nposition_mm = 5\n", b"leds = [1]",
                                 b"[camera]\nresolution_px = [1e300, 1]\n"])
def test_scene_loader_raises_only_scene_error(raw: bytes) -> None:
    with pytest.raises(SceneError):
        scene_from_toml_bytes(raw)


DEVLIST_HEADER = b"\x01\x11\x00\x05\x00\x00\x00\x00"


@pytest.mark.parametrize("raw", [DEVLIST_HEADER, DEVLIST_HEADER + b"\xff\xff\xff\xff"])
def test_usbip_devlist_decoder_raises_only_usbip_error(raw: bytes) -> None:
    with pytest.raises(UsbipError):
        decode_devlist_reply(raw)
