"""Issue 11, finding 11: `eyehil render` with a scene named ``../ESCAPED`` writes nothing outside its -o folder."""

from __future__ import annotations

from pathlib import Path

from eyehil.cli import main
from eyehil.emulator.render.cli import safe_stem


def test_scene_name_cannot_escape_the_output_folder(tmp_path: Path) -> None:
    preset = (Path(__file__).parent.parent / "emulator" / "scene" / "presets" / "guestrin2006.toml").read_text()
    scene = tmp_path / "evil.toml"
    scene.write_text(preset.replace('name = "guestrin2006"', 'name = "../ESCAPED"'))
    out = tmp_path / "out"
    assert main(["render", "-o", str(out), "--scene", str(scene), "--count", "1"]) == 0
    written = {p for p in tmp_path.rglob("*") if p.is_file()} - {scene}
    assert written and all(out in p.parents for p in written), written
    assert not list(tmp_path.glob("ESCAPED*"))


def test_safe_stem() -> None:
    assert safe_stem("../ESCAPED") == "_ESCAPED"
    assert safe_stem("/etc/passwd") == "_etc_passwd"
    assert safe_stem("...") == "scene" and safe_stem("guestrin2006") == "guestrin2006"
