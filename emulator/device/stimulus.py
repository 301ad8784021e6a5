"""The STIMULUS side channel: the emulator's stand-in for the screen and the subject in front of it.

A real eye tracker does not know what the screen shows: the host draws a target and the subject looks
at it. The emulator has no screen and no subject, so the host tells it where the target is with the
native STIMULUS message (docs/protocol.md, section 7), and the simulated subject fixates it.

This module is the one place where the device converts STIMULUS coordinates to the scene's:

- STIMULUS (protocol): mm in the screen's active area, origin at its TOP-LEFT corner as the subject
  sees it, x to the subject's RIGHT, y DOWN (the display's pixel axes scaled by the pixel pitch);
- scene screen coordinates (`eyehil.emulator.scene.Screen.to_screen`): mm from the screen CENTRE, x toward
  world +x (the subject's LEFT: the subject faces +z, so their right is world -x), y UP.

Hence x_scene = width / 2 - x_mm and y_scene = height / 2 - y_mm. Known answer, guestrin2006 screen
(377 x 301 mm): the top-left corner (0, 0) is (+188.5, +150.5) in scene coordinates, i.e. on the
subject's left and up; the centre (188.5, 150.5) is (0, 0).
"""

from __future__ import annotations

import math

from eyehil.emulator.scene import Screen

#: How far outside the active area a target may be, in screen widths/heights (beyond: INVALID_ARGUMENT).
OUTSIDE_LIMIT = 1.0


def stimulus_to_screen(screen: Screen, x_mm: float, y_mm: float) -> tuple[float, float]:
    """Scene screen coordinates (mm from the centre, x to the subject's left, y up) of a STIMULUS position."""
    width, height = screen.size
    return width / 2 - x_mm, height / 2 - y_mm


def screen_to_stimulus(screen: Screen, x: float, y: float) -> tuple[float, float]:
    """The inverse of `stimulus_to_screen`."""
    width, height = screen.size
    return width / 2 - x, height / 2 - y


def stimulus_problem(screen: Screen, x_mm: float, y_mm: float) -> str | None:
    """Why the emulator refuses a STIMULUS position (non-finite, or too far off the screen), or None."""
    if not (math.isfinite(x_mm) and math.isfinite(y_mm)):
        return "STIMULUS: position not finite"
    width, height = screen.size
    inside_x = -OUTSIDE_LIMIT * width <= x_mm <= (1 + OUTSIDE_LIMIT) * width
    inside_y = -OUTSIDE_LIMIT * height <= y_mm <= (1 + OUTSIDE_LIMIT) * height
    return None if inside_x and inside_y else "STIMULUS: position too far outside the screen"
