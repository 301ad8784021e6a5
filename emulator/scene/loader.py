"""Scene descriptions as TOML: reading and validation (every error names the key and the problem).

```toml
name = "guestrin2006"
sides = ["right"]            # eyes simulated: "right", "left"
ipd_mm = 63.0
wavelength_nm = 850.0
media = "cauchy"             # or "study-code"
[camera]
position_mm = [0.0, -150.5, 615.0]
pitch_deg = 13.75            # yaw_deg, roll_deg optional
focal_px = [4666.67, 4666.67]
principal_px = [320.0, 240.0]
resolution_px = [640, 480]
distortion = [0.0, 0.0]      # optional radial k1, k2
[[leds]]
position_mm = [188.5, 0.0, 650.0]
[screen]
centre_mm = [0.0, 0.0, 650.0]
size_mm = [377.0, 301.0]
grid = [3, 3]
[[head_positions]]           # optional; default one central position
name = "central"
offset_mm = [0.0, 0.0, 0.0]  # yaw_deg, pitch_deg, roll_deg optional
```

Whatever the bytes, `scene_from_toml_bytes` (what `load_scene` reads files with) and
`scene_from_dict` raise only `SceneError`: not UTF-8, not TOML, a wrong type anywhere, or a number out of
range (a camera of more than `MAX_RESOLUTION_PX` pixels a side, more than `MAX_LEDS` LEDs or
`MAX_HEAD_POSITIONS` head positions) all name the key and the problem.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from eyehil.emulator.optics.camera import PinholeCamera
from eyehil.emulator.scene.model import SIDES, HeadPose, Scene, SceneError, Screen
from eyehil.emulator.scene.presets_index import PRESETS, preset_names

MAX_RESOLUTION_PX = 16384
MAX_LEDS = 16
MAX_HEAD_POSITIONS = 1024
MAX_GRID = 100
KNOWN_TOP = {"name", "description", "source", "sides", "ipd_mm", "wavelength_nm", "media", "camera", "leds",
             "screen", "head_positions", "extra"}


def _table(data: Any, where: str) -> dict:
    if not isinstance(data, dict):
        raise SceneError(f"{where}: expected a table")
    return data


def _vector(data: dict, key: str, where: str, n: int, *, positive: bool = False) -> np.ndarray:
    data = _table(data, where)
    if key not in data:
        raise SceneError(f"{where}.{key}: missing (a list of {n} numbers)")
    value = data[key]
    if not (isinstance(value, list) and len(value) == n and all(isinstance(v, int | float) for v in value)):
        raise SceneError(f"{where}.{key}: expected a list of {n} numbers, got {value!r}")
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
        raise SceneError(f"{where}.{key}: values must be finite{' and > 0' if positive else ''}, got {value!r}")
    return arr


def _number(data: dict, key: str, where: str, default: float, lo: float = -np.inf, hi: float = np.inf) -> float:
    value = data.get(key, default)
    if not isinstance(value, int | float) or not lo <= value <= hi:
        raise SceneError(f"{where}.{key}: expected a number in [{lo}, {hi}], got {value!r}")
    return float(value)


def _camera(data: Any) -> PinholeCamera:
    if not isinstance(data, dict):
        raise SceneError("camera: missing table [camera]")
    return PinholeCamera.from_angles(
        position=_vector(data, "position_mm", "camera", 3),
        pitch_deg=_number(data, "pitch_deg", "camera", 0.0, -90, 90),
        yaw_deg=_number(data, "yaw_deg", "camera", 0.0, -90, 90),
        roll_deg=_number(data, "roll_deg", "camera", 0.0, -180, 180),
        focal_px=tuple(_vector(data, "focal_px", "camera", 2, positive=True)),
        principal_px=tuple(_vector(data, "principal_px", "camera", 2)),
        resolution_px=_resolution(data),
        distortion=tuple(_vector(data, "distortion", "camera", 2)) if "distortion" in data else (0.0, 0.0),
    )


def _resolution(data: dict) -> tuple[int, int]:
    px = _vector(data, "resolution_px", "camera", 2, positive=True)
    if np.any(px > MAX_RESOLUTION_PX) or np.any(px != np.round(px)):
        raise SceneError(f"camera.resolution_px: expected whole numbers in 1..{MAX_RESOLUTION_PX}")
    return int(px[0]), int(px[1])


def _leds(data: Any) -> np.ndarray:
    if not isinstance(data, list) or not data or len(data) > MAX_LEDS:
        raise SceneError("leds: expected one or more [[leds]] tables with position_mm")
    leds = np.stack([_vector(led, "position_mm", f"leds[{i}]", 3) for i, led in enumerate(data)])
    if np.any(leds[:, 2] <= 0):
        raise SceneError("leds[].position_mm: an LED must be in front of the eyes (z > 0 mm)")
    return leds


def _screen(data: Any) -> Screen:
    if not isinstance(data, dict):
        raise SceneError("screen: missing table [screen]")
    grid = _vector(data, "grid", "screen", 2, positive=True)
    if np.any(grid != np.round(grid)) or np.any(grid > MAX_GRID):
        raise SceneError(f"screen.grid: expected whole numbers, got {data['grid']!r}")
    centre = _vector(data, "centre_mm", "screen", 3)
    if centre[2] <= 0:
        raise SceneError("screen.centre_mm: the screen must be in front of the eyes (z > 0 mm)")
    size = _vector(data, "size_mm", "screen", 2, positive=True)
    return Screen(centre=centre, size=(size[0], size[1]), grid=(int(grid[0]), int(grid[1])))


def _head_positions(data: Any) -> tuple[HeadPose, ...]:
    if data is None:
        return (HeadPose(),)
    if not isinstance(data, list) or not data or len(data) > MAX_HEAD_POSITIONS:
        raise SceneError("head_positions: expected [[head_positions]] tables")
    poses = []
    for i, item in enumerate(data):
        where = f"head_positions[{i}]"
        item = _table(item, where)
        offset = _vector(item, "offset_mm", where, 3) if "offset_mm" in item else np.zeros(3)
        angles = [_number(item, k, where, 0.0, -45, 45) for k in ("yaw_deg", "pitch_deg", "roll_deg")]
        poses.append(HeadPose(str(item.get("name", f"position {i}")), *offset.tolist(), *angles))
    return tuple(poses)


def scene_from_toml_bytes(raw: bytes, origin: str = "scene") -> Scene:
    """Decode (UTF-8), parse (TOML) and validate a scene; `SceneError` for anything wrong."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{origin}: not UTF-8 ({exc.reason} at byte {exc.start})") from None
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise SceneError(f"{origin}: not valid TOML: {exc}") from None
    return scene_from_dict(data, origin)


def scene_from_dict(data: dict[str, Any], origin: str = "scene") -> Scene:
    """Build and validate a Scene from parsed TOML."""
    try:
        data = _table(data, "scene")
        unknown = set(data) - KNOWN_TOP
        if unknown:
            raise SceneError(f"{', '.join(sorted(unknown))}: unknown key(s); known: {', '.join(sorted(KNOWN_TOP))}")
        sides = data.get("sides", ["right"])
        if not (isinstance(sides, list) and sides and all(s in SIDES for s in sides) and len(set(sides)) == len(sides)):
            raise SceneError(f"sides: expected a list of distinct 'right'/'left', got {sides!r}")
        media = data.get("media", "cauchy")
        if media not in ("cauchy", "study-code"):
            raise SceneError(f"media: expected 'cauchy' or 'study-code', got {media!r}")
        return Scene(
            name=str(data.get("name", "custom")),
            camera=_camera(data.get("camera")),
            leds=_leds(data.get("leds")),
            screen=_screen(data.get("screen")),
            head_positions=_head_positions(data.get("head_positions")),
            sides=tuple(sides),
            ipd_mm=_number(data, "ipd_mm", "scene", 63.0, 40.0, 90.0),
            wavelength_nm=_number(data, "wavelength_nm", "scene", 850.0, 300.0, 2000.0),
            media=media,
            description=str(data.get("description", "")),
            source=str(data.get("source", "")),
            extra=dict(_table(data.get("extra", {}), "extra")),
        )
    except SceneError as exc:
        raise SceneError(f"{origin}: {exc}") from None
    except (ValueError, TypeError, ArithmeticError, LookupError) as exc:  # a check above missed it: still SceneError
        raise SceneError(f"{origin}: {type(exc).__name__}: {exc}") from None


def load_scene(name_or_path: str | Path) -> Scene:
    """A preset by name (`guestrin2006`, `blignaut2014`, ...) or a TOML file path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise SceneError(f"scene file {path} does not exist")
        raw, origin = path.read_bytes(), str(path)
    else:
        res = PRESETS / f"{name_or_path}.toml"
        if not res.is_file():
            raise SceneError(f"unknown scene {name_or_path!r}; presets: {', '.join(preset_names())}")
        raw, origin = res.read_bytes(), f"preset {name_or_path}"
    return scene_from_toml_bytes(raw, origin)


