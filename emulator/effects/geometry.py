"""The set-up's geometry as it really is: LEDs and screen not where the host believes.

Frame: the scene frame of `eyehil.emulator.scene` (mm; x to the subject's left, y up, z toward screen and
camera). The host keeps the nominal scene (`eyehil.analysis.study.bridge.tracker_geometry`), so these are errors of a
measured set-up.

- `LedPosition`: every LED displaced by (dx, dy) mm. A model-based host computes the corneal centre from
  the LEDs' positions; a common shift moves the reconstructed centre, which the calibration partly absorbs
  at the calibration head position and not elsewhere.
- `ScreenPosition`: the screen (and so every target) displaced by (dx, dy) mm in its plane. The
  calibration absorbs a constant angular offset at the calibration position into (alpha, beta); the
  offset is a different angle at another head position or depth.
- `ScreenTilt`: the screen turned about its centre by `tilt_deg` (about x; + top toward the subject)
  and `yaw_deg` (about y; + the +x edge toward the subject): the targets leave the plane the host
  intersects the visual axis with, by up to size/2 x sin(angle).

Reference: Guestrin & Eizenman 2006 (IEEE TBME 53(6):1124-1133: the system geometry is assumed known
from a calibration of the set-up); Model & Eizenman 2010 (IEEE TBME 57(5):1031-1039, user-calibration
and set-up errors); Barsingerhorn, Boonstra & Goossens 2018 (Behav Res Methods 50:1776-1791; the
effect of LED and screen geometry errors on a model-based tracker).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from eyehil.emulator.effects.base import Effect, Parameter
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.scene import Scene, Screen

REFERENCE = ("Guestrin & Eizenman 2006, IEEE TBME 53(6):1124-1133; Model & Eizenman 2010, IEEE TBME "
             "57(5):1031-1039; Barsingerhorn et al. 2018, Behav Res Methods 50:1776-1791")


class LedPosition(Effect):
    """Every LED displaced from its nominal position by (dx, dy) mm."""

    name = "led_position"
    reference = REFERENCE
    prior = "0 +- 5 mm for LEDs placed by hand and measured with a ruler"
    parameters = (
        Parameter("dx_mm", "mm", 0.0, -30.0, 30.0, doc="scene x (subject's left)"),
        Parameter("dy_mm", "mm", 0.0, -30.0, 30.0, doc="scene y (up)"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        return eyes, scene.with_leds(scene.leds + np.array([values["dx_mm"], values["dy_mm"], 0.0]))


class ScreenPosition(Effect):
    """The screen displaced in its plane by (dx, dy) mm from its nominal position."""

    name = "screen_position"
    reference = REFERENCE
    prior = "0 +- 5 mm for a screen measured with a ruler"
    parameters = (
        Parameter("dx_mm", "mm", 0.0, -40.0, 40.0, doc="scene x (subject's left)"),
        Parameter("dy_mm", "mm", 0.0, -40.0, 40.0, doc="scene y (up)"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        screen = replace(scene.screen, centre=scene.screen.centre + np.array([values["dx_mm"], values["dy_mm"], 0.0]))
        return eyes, replace(scene, screen=screen)


@dataclass(frozen=True)
class TiltedScreen(Screen):
    """A `Screen` turned about its centre: `tilt_deg` about x (+ top toward the subject, -z), `yaw_deg`
    about y (+ the +x edge toward the subject)."""

    tilt_deg: float = 0.0
    yaw_deg: float = 0.0

    def targets(self) -> np.ndarray:
        offsets = super().targets() - self.centre
        t, y = np.radians(self.tilt_deg), np.radians(self.yaw_deg)
        tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(t), np.sin(t)], [0.0, -np.sin(t), np.cos(t)]])
        yaw = np.array([[np.cos(y), 0.0, np.sin(y)], [0.0, 1.0, 0.0], [-np.sin(y), 0.0, np.cos(y)]])
        return self.centre + offsets @ (yaw @ tilt).T


class ScreenTilt(Effect):
    """The screen turned about its centre (deg about x, deg about y) from the plane the host assumes."""

    name = "screen_tilt"
    reference = REFERENCE
    prior = "0 +- 3 deg for a monitor set up by eye"
    parameters = (
        Parameter("tilt_deg", "deg", 0.0, -15.0, 15.0, doc="about scene x, + top toward the subject"),
        Parameter("yaw_deg", "deg", 0.0, -15.0, 15.0, doc="about scene y, + the +x edge toward the subject"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        s = scene.screen
        tilt = float(values["tilt_deg"]) + getattr(s, "tilt_deg", 0.0)
        yaw = float(values["yaw_deg"]) + getattr(s, "yaw_deg", 0.0)
        return eyes, replace(scene, screen=TiltedScreen(s.centre, s.size, s.grid, tilt, yaw))
