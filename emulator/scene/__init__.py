"""Scenes: where the camera, the LEDs, the screen and its targets, and the head positions are.

- `model`: `Scene`, `Screen`, `HeadPose`, `SceneError` (frames and units in its docstring);
- `loader`: `load_scene(name_or_path)` (a preset or a TOML file, every error naming the key), `preset_names`;
- `presets/*.toml`: guestrin2006, guestrin2006-table3, blignaut2014.
"""

from eyehil.emulator.scene.loader import load_scene, preset_names, scene_from_dict, scene_from_toml_bytes
from eyehil.emulator.scene.model import SIDES, HeadPose, Scene, SceneError, Screen

__all__ = ["SIDES", "HeadPose", "Scene", "SceneError", "Screen", "load_scene", "preset_names", "scene_from_dict",
           "scene_from_toml_bytes"]
