"""Bad input is refused clearly: eye anatomy, scene files; and the CLI of the forward model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eyehil.cli import main
from eyehil.emulator.eye.media import Media, cauchy_index
from eyehil.emulator.eye.normative import normative_eye
from eyehil.emulator.scene import SceneError, load_scene, preset_names

GOOD = """
name = "mine"
[camera]
position_mm = [0.0, -150.0, 600.0]
pitch_deg = 14.0
focal_px = [4000.0, 4000.0]
principal_px = [320.0, 240.0]
resolution_px = [640, 480]
[[leds]]
position_mm = [100.0, 0.0, 600.0]
[screen]
centre_mm = [0.0, 0.0, 650.0]
size_mm = [300.0, 200.0]
grid = [3, 3]
"""


def _write(tmp_path, text: str):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


def test_a_valid_user_scene_loads(tmp_path) -> None:
    scene = load_scene(_write(tmp_path, GOOD))
    assert scene.name == "mine" and scene.leds.shape == (1, 3) and len(scene.targets()) == 9


@pytest.mark.parametrize(("change", "key"), [
    (("focal_px = [4000.0, 4000.0]", "focal_px = [-4000.0, 4000.0]"), "camera.focal_px"),
    (("position_mm = [100.0, 0.0, 600.0]", "position_mm = [100.0, 0.0, -5.0]"), "leds[].position_mm"),
    (("grid = [3, 3]", "grid = [3]"), "screen.grid"),
    (("size_mm = [300.0, 200.0]", 'size_mm = "big"'), "screen.size_mm"),
    (('name = "mine"', 'name = "mine"\nsides = ["middle"]'), "sides"),
    (('name = "mine"', 'name = "mine"\nwavelenght_nm = 850'), "wavelenght_nm"),
    (("pitch_deg = 14.0", "pitch_deg = 140.0"), "camera.pitch_deg"),
    (("centre_mm = [0.0, 0.0, 650.0]", "centre_mm = [0.0, 0.0, -650.0]"), "screen.centre_mm"),
])
def test_a_bad_scene_names_the_key(tmp_path, change, key: str) -> None:
    with pytest.raises(SceneError) as err:
        load_scene(_write(tmp_path, GOOD.replace(*change)))
    assert key in str(err.value)


def test_malformed_toml_and_missing_tables_are_refused(tmp_path) -> None:
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(_write(tmp_path, "name = \n"))
    with pytest.raises(SceneError, match=r"camera: missing table \[camera\]"):
        load_scene(_write(tmp_path, 'name = "x"\n'))
    with pytest.raises(SceneError, match="unknown scene"):
        load_scene("no-such-preset")


def test_every_preset_loads() -> None:
    assert {"guestrin2006", "blignaut2014"} <= set(preset_names())
    for name in preset_names():
        assert load_scene(name).name == name


@pytest.mark.parametrize(("field", "value", "message"), [
    ("anterior_radius", -7.8, "anterior_radius must be > 0"),
    ("anterior_conic", -1.0, "ellipsoid"),
    ("posterior_conic", -1.3, "ellipsoid"),
    ("pupil_radius", 7.0, "smaller than limbus"),
    ("cct", np.nan, "not finite"),
    ("axial_length", 5.0, "vitreous"),
])
def test_impossible_anatomy_is_refused(field: str, value: float, message: str) -> None:
    eye = normative_eye("navarro")
    with pytest.raises(ValueError, match=message):
        eye.replace(**{field: value})


def test_media_indices() -> None:
    assert cauchy_index("cornea", 850) == pytest.approx(1.37017, abs=5e-6)
    assert cauchy_index("vitreous", 850) == pytest.approx(1.33047, abs=5e-6)
    with pytest.raises(ValueError, match="unknown medium"):
        cauchy_index("honey", 850)
    with pytest.raises(ValueError, match="wavelength"):
        Media.cauchy(50)


def test_simulate_cli_prints_a_summary_and_saves(tmp_path, capsys) -> None:
    out = tmp_path / "f.npz"
    assert main(["simulate", "--eyes", "sample:3", "--quiet", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "fixations" in text and "135 = 3 eyes x 1 side(s) x 5 head position(s) x 9 targets" in text
    assert out.exists() and "pupil_centre_px" in np.load(out)


def test_simulate_cli_reports_bad_input(capsys) -> None:
    assert main(["simulate", "--eyes", "sample:0", "--quiet"]) == 2
    assert "positive count" in capsys.readouterr().err


def test_simulate_warns_about_a_head_position_with_no_valid_fixation(tmp_path, capsys) -> None:
    """Issue 17: a head 2 m forward ran with exit 0 and only 'valid 0' to show for it; now a warning says where
    and why, and the set-up that works gives no such warning."""
    preset = (Path(__file__).resolve().parent.parent / "emulator" / "scene" / "presets" / "guestrin2006.toml")
    far = tmp_path / "far.toml"
    far.write_text(preset.read_text().replace("offset_mm = [0.0, 0.0, 0.0]", "offset_mm = [0.0, 0.0, 2000.0]", 1))
    assert main(["simulate", "--scene", str(far), "--eyes", "sample:2", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "head position 'central' (at 0, 0, 2000 mm): no valid fixation of 18 (the fixation solve failed" in err
    assert main(["simulate", "--scene", "blignaut2014", "--eyes", "sample:2", "--quiet"]) == 0
    assert "no valid fixation" not in capsys.readouterr().err
