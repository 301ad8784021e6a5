"""Scenes: camera, LEDs, screen and targets, head positions, IPD and wavelength.

Frame: the scene (world) frame is the head frame of DESIGN.md with the head at its reference
(central) position: origin midway between the unrotated anterior corneal apices, x to the subject's
left, y up, z forward toward screen and camera; mm. A head pose moves the head in this frame (the
published study subtracted the head offset from camera and screen positions: the same thing).

The screen is a rectangle in a plane z = const facing the subject. Targets form a grid over the
whole screen (corners included), numbered column by column (`index = column * rows + row`), column 0
at the +x edge, row 0 at the top (the numbering of the Blignaut 2014 calibration sets).

Presets live in `emulator/scenes/*.toml`; `load_scene(name_or_path)` reads one and validates it, and a
bad file is refused with an error naming the key and the problem (`SceneError`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.emulator.optics.camera import PinholeCamera

SIDES = ("right", "left")


class SceneError(ValueError):
    """A scene description is malformed; the message names the key."""


@dataclass(frozen=True)
class HeadPose:
    """Head position in the scene: translation (mm) and rotation (deg; yaw about y toward +x, pitch about x
    up, roll about z), applied as X_scene = R X_head + t."""

    name: str = "central"
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0

    @property
    def translation(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z])

    @property
    def rotation(self) -> np.ndarray:
        """Head -> scene rotation (3, 3)."""
        from eyehil.emulator.fixation import _rotations

        rt, re, ra = _rotations(*(np.radians(np.array(a)) for a in (self.yaw, self.pitch, self.roll)))
        return ra @ re @ rt

    def to_head(self, points: np.ndarray) -> np.ndarray:
        """Scene points (..., 3) in this head's frame."""
        return (points - self.translation) @ self.rotation


@dataclass(frozen=True)
class Screen:
    """A screen facing the subject: centre (mm), size (w, h mm), target grid (columns, rows)."""

    centre: np.ndarray
    size: tuple[float, float]
    grid: tuple[int, int]

    def targets(self) -> np.ndarray:
        """(columns * rows, 3) target positions in the scene frame, numbered as in the module docstring."""
        cols, rows = self.grid
        xs = np.linspace(self.size[0] / 2, -self.size[0] / 2, cols) if cols > 1 else np.zeros(1)
        ys = np.linspace(self.size[1] / 2, -self.size[1] / 2, rows) if rows > 1 else np.zeros(1)
        x, y = np.meshgrid(xs, ys, indexing="ij")
        offsets = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=-1)
        return self.centre + offsets

    def to_screen(self, points: np.ndarray) -> np.ndarray:
        """Scene points (..., 3) on the screen plane as (x, y) mm from the screen centre (x toward +x, y up)."""
        return points[..., :2] - self.centre[:2]


@dataclass(frozen=True)
class Scene:
    """A tracker set-up; see the module docstring for the frame."""

    name: str
    camera: PinholeCamera
    leds: np.ndarray  # (n_leds, 3) mm
    screen: Screen
    head_positions: tuple[HeadPose, ...] = (HeadPose(),)
    sides: tuple[str, ...] = ("right",)
    ipd_mm: float = 63.0
    wavelength_nm: float = 850.0
    media: str = "cauchy"
    description: str = ""
    source: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        leds = np.asarray(self.leds, dtype=float)
        if leds.ndim != 2 or leds.shape[1] != 3 or len(leds) == 0:
            raise SceneError(f"leds: expected (n, 3) positions in mm, got shape {leds.shape}")
        if not np.all(np.isfinite(leds)) or np.any(leds[:, 2] <= 0):
            raise SceneError("leds: every LED must be finite and in front of the eyes (z > 0 mm)")
        if any(s not in SIDES for s in self.sides) or not self.sides:
            raise SceneError(f"sides: expected 'right' and/or 'left', got {self.sides!r}")
        object.__setattr__(self, "leds", leds)

    def apex(self, side: str) -> np.ndarray:
        """Unrotated anterior corneal apex of the `side` eye in the head frame (mm)."""
        return np.array([-self.ipd_mm / 2 if side == "right" else self.ipd_mm / 2, 0.0, 0.0])

    def targets(self) -> np.ndarray:
        return self.screen.targets()

    def with_leds(self, leds: np.ndarray) -> Scene:
        return replace(self, leds=np.asarray(leds, dtype=float).reshape(-1, 3))


def load_scene(name_or_path: str | Path) -> Scene:
    """A preset by name (`guestrin2006`, `blignaut2014`, ...) or a TOML file path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise SceneError(f"scene file {path} does not exist")
        text, origin = path.read_text(encoding="utf-8"), str(path)
    else:
        res = resources.files("eyehil.emulator") / "scenes" / f"{name_or_path}.toml"
        if not res.is_file():
            raise SceneError(f"unknown scene {name_or_path!r}; presets: {', '.join(preset_names())}")
        text, origin = res.read_text(encoding="utf-8"), f"preset {name_or_path}"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: not valid TOML: {exc}") from exc
    from eyehil.emulator.scene.loader import scene_from_dict

    return scene_from_dict(data, origin)


def preset_names() -> list[str]:
    """Names of the bundled scene presets."""
    return sorted(p.name[:-5] for p in (resources.files("eyehil.emulator") / "scenes").iterdir() if p.name.endswith(".toml"))
