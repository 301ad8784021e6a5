"""Glints: the point of the anterior cornea that reflects an LED into the camera's nodal point.

In the eye-local frame (the unrotated eye frame; the cornea a conic about z or a `Biconic`) the glint G of an LED
at L seen by a camera whose nodal point is O satisfies the law of reflection: the surface normal at G
bisects the unit directions from G to L and from G to O. Unknowns: (x, y) of G, with z on the
surface; residual n(G) - unit(unit(L - G) + unit(O - G)) (its x, y parts); a few quasi-Newton steps
(Broyden, `secant2d`) from the glint of the osculating sphere. (For a biconic the unknowns are the
surface coordinates (x', y') of `Biconic.point`; the residual is still the eye-local x, y parts, which
vanish together with the z part on the cap.) Accuracy is reported as the distance (mm) by which the
reflected ray misses O (the published study required 1e-4 mm).

A glint is invalid when it falls off the cornea (beyond the limbus / aperture) or the surface there
does not face both the LED and the camera.

Known answer (sphere of radius R centred at C, LED and camera both at the same point P): the glint is
C + R unit(P - C).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.optics.biconic import Biconic
from eyehil.emulator.optics.conic import Conic
from eyehil.emulator.optics.newton import secant2d
from eyehil.emulator.optics.rays import _dot, distance_to_line, reflect, unit

GLINT_TOLERANCE_MM = 1e-4


@dataclass(frozen=True)
class Glints:
    """Glint points (..., 3) in the eye-local frame, the miss distance (mm) and validity."""

    point: np.ndarray
    residual_mm: np.ndarray
    valid: np.ndarray


def solve_glints(cornea: Conic | Biconic, led: np.ndarray, camera: np.ndarray) -> Glints:
    """Glints on `cornea` for LEDs `led` (..., 3) and camera nodal points `camera` (..., 3), eye-local mm."""

    def residual(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g, exists = cornea.point(q)
        n = cornea.normal(g)
        to_led, to_cam = unit(led - g), unit(camera - g)
        ok = exists & (_dot(n, to_led) > 0) & (_dot(n, to_cam) > 0)
        return (n - unit(to_led + to_cam))[..., :2], ok

    centre, radius = cornea.osculating_sphere()
    start = centre + radius[..., None] * unit(unit(led - centre) + unit(camera - centre))
    sol = secant2d(residual, cornea.coords(start), max_step=0.5, subset=False)
    g, exists = cornea.point(sol.q)
    n = cornea.normal(g)
    miss = distance_to_line(camera, g, reflect(unit(g - led), n))
    valid = sol.ok & exists & (miss <= GLINT_TOLERANCE_MM)
    return Glints(point=g, residual_mm=miss, valid=valid)
