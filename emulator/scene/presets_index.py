"""The bundled scene presets (`presets/*.toml`) by name, without importing numpy (the CLI's help lists them)."""

from __future__ import annotations

from importlib import resources
from importlib.abc import Traversable

PRESETS: Traversable = resources.files(__package__) / "presets"


def preset_names() -> list[str]:
    """Names of the bundled scene presets."""
    return sorted(p.name[:-5] for p in PRESETS.iterdir() if p.name.endswith(".toml"))
