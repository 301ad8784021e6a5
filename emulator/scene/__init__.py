"""Scenes: where the camera, the LEDs, the screen and its targets, and the head positions are.

- `model`: `Scene`, `Screen`, `HeadPose`, `SceneError` (frames and units in its docstring);
- `loader`: `load_scene(name_or_path)` (a preset or a TOML file, every error naming the key), `preset_names`;
- `presets/*.toml`: guestrin2006, guestrin2006-table3, blignaut2014; `presets_index`: `preset_names` (no numpy).

The names below are loaded on first use, so that a command's help can list the presets without numpy.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {"SIDES": "model", "HeadPose": "model", "Scene": "model", "SceneError": "model", "Screen": "model",
            "load_scene": "loader", "scene_from_dict": "loader", "scene_from_toml_bytes": "loader",
            "preset_names": "presets_index"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
