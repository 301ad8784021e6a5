"""Effects on the scene the simulation sees, which the host does not know about.

## Lens distortion (`LensDistortion`)

Radial lens distortion of the tracker's camera that the host does not correct.

Frame: normalised camera coordinates x = X_c / Z_c (dimensionless, camera frame of
`eyehil.emulator.optics.camera`). The simulated camera maps x to x (1 + k1 r^2 + k2 r^4), r = |x|, before the
intrinsics (Brown 1966 / OpenCV radial model); this effect sets k1 and keeps the scene's k2. The host keeps
its nominal pinhole geometry (`eyehil.analysis.study.bridge.tracker_geometry` of the undistorted scene), as a tracker
whose lens was never calibrated would.

Scale: the Guestrin 2006 camera (f = 4667 px, 640 x 480 px) sees about +-0.07 in x; the right eye sits at
r ~ 0.05 at the central head position and near r ~ 0.1 when the head moves 30 mm sideways (off the sensor;
the replication keeps such extrapolated features). A displacement k1 r^3 f is 4.7 k1 px at r = 0.1, and
what matters is its change across the pupil-glint vector, 3 k1 r^2 (3 % of it for k1 = 1 at r = 0.1).
Narrow-field machine-vision lenses have |k1| of order 0.1-1 in these units; the plausible range below is
generous. Reference: D. C. Brown, "Decentering distortion of lenses", Photogramm. Eng. 32(3):444-462, 1966.

## Head roll (`HeadRoll`)

Head roll at the validation head positions: the eye's torsion changes after calibration.

Frame: the head pose of `eyehil.emulator.scene.HeadPose` (roll about the scene z axis, deg). At every head
position but the first (the calibration position), the head is rolled by `roll_deg` in addition to its
pose. The eyes follow Listing's law in the head frame, so they roll with the head; real eyes counter-roll
by only about a tenth of a static head tilt (ocular counter-roll; Collewijn, Van der Steen, Ferman &
Jansen 1985, Exp Brain Res 59:185-196), so `roll_deg` stands for the net torsion change.

Why it matters: the Guestrin & Eizenman 2006 visual axis adds the calibrated angles (alpha, beta) to the
optic axis angles in the world frame (angle addition, no torsion term). A torsion change rho turns the
true visual axis about the optic axis, an error of about |kappa| rho (kappa ~ 5 deg: 0.44 deg for
rho = 5 deg) that no head translation produces. A subject who tilts the head while moving it 30 mm
sideways does exactly this.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from eyehil.emulator.effects.base import Effect, Parameter
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.scene import Scene


class LensDistortion(Effect):
    """Uncorrected radial distortion k1 of the camera (dimensionless, normalised coordinates)."""

    name = "lens_distortion"
    reference = "Brown 1966, Photogramm. Eng. 32(3):444-462"
    prior = "|k1| 0.1-1 for narrow-field machine-vision lenses (normalised coordinates)"
    parameters = (
        Parameter("k1", "", 0.0, -3.0, 3.0, doc="radial coefficient: x' = x (1 + k1 r^2 + k2 r^4)"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        camera = replace(scene.camera, distortion=(float(values["k1"]), scene.camera.distortion[1]))
        return eyes, replace(scene, camera=camera)


class HeadRoll(Effect):
    """Head (and eye) roll added at the validation head positions (deg)."""

    name = "head_roll"
    reference = "Guestrin & Eizenman 2006, IEEE TBME 53(6); Collewijn et al. 1985, Exp Brain Res 59:185-196"
    validation_only = True
    prior = "0 +- 3 deg net torsion change for a free head"
    parameters = (
        Parameter("roll_deg", "deg", 0.0, -8.0, 8.0, doc="roll about the scene z axis, + per HeadPose.roll"),
    )

    def apply(self, eyes: EyeModel, scene: Scene, values: Mapping[str, float],
              session: str) -> tuple[EyeModel, Scene]:
        if session != "validation":
            return eyes, scene
        roll = float(values["roll_deg"])
        heads = tuple(replace(h, roll=h.roll + roll) for h in scene.head_positions)
        return eyes, replace(scene, head_positions=heads)
