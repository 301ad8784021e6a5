"""Image-plane geometry of the eyes that `eyehil.emulator.render.renderer` draws (pure, batched numpy).

Everything here is computed from the forward model's Features (arrays shaped (E, S, H, T, ...), scene
frame mm, image px), the eyes (anatomy as right eyes) and the scene, and is returned per sample in
full-sensor pixels (OpenCV convention: origin at the top-left pixel centre, x right, y down):

- pupil: the ray-traced refracted boundary (`Features.pupil_points_px`, N points evenly spaced around
  the stop) is interpolated by its trigonometric (Fourier) series into a dense closed curve, stored as
  a polar table r(theta) about the fitted ellipse centre, the ground truth `Features.pupil_centre_px`.
  Samples with blocked boundary points use the fitted ellipse instead.
- limbus: the corneal edge, where the anterior cornea meets the sclera: the anterior surface's points at
  distance `EyeModel.limbus_radius` r_l from its own axis (the edge of the cap `eye.surfaces.biconic_cornea`
  traces), surface coordinates (x', y') = r_l (cos t, sin t) at the biconic sag of each meridian, so a toric
  cornea's edge lies deeper in its flatter meridian, and a tilted or displaced cornea carries it along. In the
  eye-local frame these are placed by the sample's pose (`fixation.posed` of the Features' azimuth, elevation
  and torsion) and head position, as the forward model places the cornea. For a cornea of revolution (R, Q)
  this is the circle at the sag depth w = r_l^2 / (R (1 + sqrt(1 - (1 + Q) r_l^2 / R^2))) about the optic
  axis. The image is the least-squares ellipse of 24 projected points (exact for the circle and an
  undistorted pinhole camera; the edge of a toric cornea is not planar, its image departs from an ellipse by
  far less than a pixel).
- glints: `Features.glint_px` and `Features.glint_valid`.
- eyelids: margins fixed to the head, between a nasal and a temporal canthus (`Eyelids`, eye frame mm,
  right-eye numbers with x nasal, mirrored for left eyes). At eye-frame x the margin height is
  y(x) = y_c(x) + h (1 - s^2), y_c the straight line through the canthi, s = x / x_nasal for x > 0 and
  x / |x_temporal| otherwise, h the height above y_c at x = 0; the margin lies on a sphere of radius
  `margin_radius_mm` about (0, 0, -`margin_centre_mm`), clamped to the canthi's depth behind it.
  Gaze: with dy the posed apex's rise in the head frame (mm, about 13 sin(elevation)), the margins at
  x = 0 are upper_mm + upper_follow dy and lower_mm + lower_follow dy; a blink b in [0, 1] moves the
  upper lid to upper + b (lower - upper) (closed at b = 1).

Known answer: with blink 1 the upper and lower margins coincide point for point.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.surfaces import biconic_cornea
from eyehil.emulator.features import Features
from eyehil.emulator.fixation import eye_centres, posed
from eyehil.emulator.forward import Placement
from eyehil.emulator.optics.ellipse import fit_ellipse
from eyehil.emulator.scene import Scene

LIMBUS_POINTS = 24
POLAR_SAMPLES = 128


@dataclass(frozen=True)
class Eyelids:
    """Lid margins (see the module docstring); eye frame mm of a right eye (x nasal, y up, z forward)."""

    nasal_canthus_mm: tuple[float, float, float] = (13.0, -1.0, -6.0)
    temporal_canthus_mm: tuple[float, float, float] = (-15.0, 0.5, -8.0)
    upper_mm: float = 4.4  # upper margin height at x = 0 in primary gaze
    lower_mm: float = -5.3
    upper_follow: float = 0.9  # lid rise (mm) per mm of apex rise
    lower_follow: float = 0.4
    margin_centre_mm: float = 12.0  # the margin sphere's centre lies this far behind the rest apex
    margin_radius_mm: float = 12.5
    n_points: int = 33


@dataclass(frozen=True, eq=False)
class EyeOutline:
    """Image geometry of a batch of eye samples (leading `shape`), full-sensor px; see the module docstring.

    The polar pupil table holds, per sample, angles theta (M,) ascending in (-pi, pi], radii r (M,) px and
    dr/dtheta (M,) px/rad about `pupil_centre_px`. Lids are polylines (K, 2) from canthus to canthus."""

    pupil_centre_px: np.ndarray
    pupil_axes_px: np.ndarray
    pupil_angle_deg: np.ndarray
    pupil_valid: np.ndarray
    pupil_points_px: np.ndarray
    pupil_theta: np.ndarray
    pupil_r: np.ndarray
    pupil_dr: np.ndarray
    limbus_centre_px: np.ndarray
    limbus_axes_px: np.ndarray
    limbus_angle_deg: np.ndarray
    glint_px: np.ndarray
    glint_valid: np.ndarray
    upper_lid_px: np.ndarray
    lower_lid_px: np.ndarray
    px_per_mm: np.ndarray
    sensor_px: tuple[int, int]

    @property
    def shape(self) -> tuple[int, ...]:
        return self.pupil_valid.shape

    def __getitem__(self, index) -> EyeOutline:
        """The samples at `index` of the leading axes (numpy indexing)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return EyeOutline(**{k: v if k == "sensor_px" else v[index] for k, v in values.items()})


def eye_outlines(features: Features, eyes: EyeModel, scene: Scene, *, blink: float | np.ndarray = 0.0,
                 lids: Eyelids | None = None) -> EyeOutline:
    """The outline of every sample of `features` (E, S, H, T) of `eyes` (E) in `scene`; `blink` in [0, 1]
    broadcasts against (E, S, H, T)."""
    lids = lids or Eyelids()
    eyes = eyes.as_batch()
    pad = (slice(None), None, None, None)
    limbus = limbus_ellipse(features, eyes, scene)
    upper, lower = lid_margins(features, scene, lids, np.clip(blink, 0.0, 1.0))
    theta, r, dr = pupil_polar(features.pupil_points_px, features.pupil_points_valid, features.pupil_centre_px,
                               features.pupil_axes_px, features.pupil_angle_deg)
    return EyeOutline(
        pupil_centre_px=features.pupil_centre_px, pupil_axes_px=features.pupil_axes_px,
        pupil_angle_deg=features.pupil_angle_deg, pupil_valid=features.pupil_valid & features.fixation_valid,
        pupil_points_px=features.pupil_points_px, pupil_theta=theta, pupil_r=r, pupil_dr=dr,
        limbus_centre_px=limbus.centre, limbus_axes_px=limbus.axes, limbus_angle_deg=limbus.angle_deg,
        glint_px=features.glint_px, glint_valid=features.glint_valid, upper_lid_px=upper, lower_lid_px=lower,
        px_per_mm=limbus.axes[..., 0] / (2.0 * eyes.limbus_radius[pad]), sensor_px=scene.camera.resolution_px,
    )


def limbus_ellipse(features: Features, eyes: EyeModel, scene: Scene):
    """The image ellipse (`optics.ellipse.Ellipse`, px, shape (E, S, H, T)) of the corneal edge of each sample."""
    px, _ = scene.camera.project(limbus_points(features, eyes, scene))
    return fit_ellipse(px)


def limbus_points(features: Features, eyes: EyeModel, scene: Scene, n: int = LIMBUS_POINTS) -> np.ndarray:
    """(E, S, H, T, n, 3) scene-frame points (mm) of the corneal edge of each sample (module docstring), at the
    surface angles t = 2 pi k / n of the anterior cornea's first principal meridian frame."""
    eyes = eyes.as_batch()
    t = 2.0 * np.pi * np.arange(n) / n
    out = np.empty((*features.pupil_valid.shape, n, 3))
    for s, side in enumerate(features.sides):
        eye = eyes.with_laterality(side)
        anterior = biconic_cornea(eye)[0].reshaped(1)
        q = eye.limbus_radius[:, None, None] * np.stack([np.cos(t), np.sin(t)], axis=-1)  # (E, n, 2)
        local, _ = anterior.point(q)  # on the cap's edge: existence is not required there
        centres = tuple(c[:, None, None, :] for c in eye_centres(eye))
        a, b = posed(centres, features.azimuth_deg[:, s], features.elevation_deg[:, s], features.torsion_deg[:, s])
        p_eye = np.einsum("ehtij,enj->ehtni", a, local) + b[..., None, :]
        out[:, s] = Placement.of(tuple(features.head_positions), scene.apex(side)).eye_to_scene(p_eye)
    return out


def lid_margins(features: Features, scene: Scene, lids: Eyelids, blink: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower lid polylines (E, S, H, T, K, 2) px from canthus to canthus, by increasing image x."""
    heads = features.head_positions
    rot = np.stack([h.rotation for h in heads])  # (H, 3, 3) head -> scene
    shift = np.stack([h.translation for h in heads])
    apex_head = np.einsum("eshti,hij->eshtj", features.apex - shift[:, None], rot)
    dy = apex_head[..., 1]
    upper = lids.upper_mm + lids.upper_follow * dy
    lower = lids.lower_mm + lids.lower_follow * dy
    upper = upper + blink * (lower - upper)
    sign = np.array([1.0 if s == "right" else -1.0 for s in features.sides])
    rest_apex = np.stack([scene.apex(s) for s in features.sides])  # (S, 3) head frame
    out = []
    for height in (upper, lower):
        local = _margin(lids, height)  # (E, S, H, T, K, 3) eye frame of a right eye
        local = local * np.stack([sign, np.ones_like(sign), np.ones_like(sign)], -1)[:, None, None, None, :]
        head = local + rest_apex[:, None, None, None, :]
        scene_pts = np.einsum("hij,eshtkj->eshtki", rot, head) + shift[:, None, None, :]
        px = scene.camera.project(scene_pts)[0]
        order = np.argsort(np.nan_to_num(px[..., 0]), axis=-1)
        out.append(np.take_along_axis(px, order[..., None], axis=-2))
    return out[0], out[1]


def _margin(lids: Eyelids, height: np.ndarray) -> np.ndarray:
    """Margin points (..., K, 3) for centre heights (...) mm, eye frame of a right eye."""
    (xn, yn, zn), (xt, yt, zt) = lids.nasal_canthus_mm, lids.temporal_canthus_mm
    x = np.linspace(xn, xt, lids.n_points)
    s = np.where(x > 0, x / xn, x / abs(xt))
    line = yn + (yt - yn) * (x - xn) / (xt - xn)
    y0 = yn + (yt - yn) * (0.0 - xn) / (xt - xn)
    y = line + (height[..., None] - y0) * (1.0 - s**2)
    canthus_z = zn + (zt - zn) * (x - xn) / (xt - xn)
    z = -lids.margin_centre_mm + np.sqrt(np.maximum(lids.margin_radius_mm**2 - x**2 - y**2, 0.0))
    z = np.maximum(z, canthus_z)
    return np.stack([np.broadcast_to(x, y.shape), y, z], axis=-1)


def pupil_polar(points: np.ndarray, valid: np.ndarray, centre: np.ndarray, axes: np.ndarray, angle_deg: np.ndarray,
                m: int = POLAR_SAMPLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Polar tables (theta, r, dr/dtheta), each (..., m), of the pupil outline about `centre` (..., 2) px: the
    trigonometric interpolation of the outline's evenly spaced points (..., n, 2) onto m angles, or the
    ellipse (centre, full `axes`, `angle_deg`) where any point is not `valid` (..., n)."""
    upsample = _upsampler(points.shape[-2], m)  # (n, m)
    flat = np.nan_to_num(points)
    x, y = flat[..., 0] @ upsample, flat[..., 1] @ upsample
    dx, dy = x - centre[..., 0:1], y - centre[..., 1:2]
    traced = np.all(valid, axis=-1, keepdims=True)
    if not traced.all():  # the ellipse where the outline is not whole
        cos_t, sin_t = _circle(m)
        a, b, phi = axes[..., 0:1] / 2, axes[..., 1:2] / 2, np.radians(angle_deg)[..., None]
        ex, ey = a * cos_t, b * sin_t
        c, s = np.cos(phi), np.sin(phi)
        dx = np.where(traced, dx, ex * c - ey * s)
        dy = np.where(traced, dy, ex * s + ey * c)
    theta = np.arctan2(np.nan_to_num(dy), np.nan_to_num(dx))
    order = np.argsort(theta, axis=-1)
    theta = np.take_along_axis(theta, order, axis=-1)
    r = np.take_along_axis(np.hypot(dx, dy), order, axis=-1)
    both = np.stack([theta, r])
    following = np.concatenate([both[..., 1:], both[..., :1]], axis=-1)  # around the outline (np.roll, faster)
    preceding = np.concatenate([both[..., -1:], both[..., :-1]], axis=-1)
    step = following - preceding
    span = np.mod(step[0], 2.0 * np.pi)
    dr = step[1] / np.where(span > 0, span, np.inf)
    return theta, r, dr


@functools.lru_cache(maxsize=8)
def _circle(m: int) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of m evenly spaced angles 2 pi k / m (read-only)."""
    t = 2.0 * np.pi * np.arange(m) / m
    out = np.cos(t), np.sin(t)
    for a in out:
        a.setflags(write=False)
    return out


@functools.lru_cache(maxsize=8)
def _upsampler(n: int, m: int) -> np.ndarray:
    """The real matrix (n, m) of trigonometric interpolation of n evenly spaced periodic samples onto m > n: row
    k is the interpolant of the k-th unit sample (FFT, zero-padded spectrum, the Nyquist term split between
    +n/2 and -n/2, inverse FFT). A real operator: it maps x and y apart."""
    spec = np.fft.fft(np.eye(n), axis=-1)
    out = np.zeros((n, m), dtype=complex)
    h = (n + 1) // 2  # frequencies 0 .. h-1 and -(n-h) .. -1
    out[:, :h] = spec[:, :h]
    out[:, m - (n - h):] = spec[:, h:]
    if n % 2 == 0:
        out[:, n // 2] = spec[:, n // 2] / 2
        out[:, m - n // 2] = spec[:, n // 2] / 2
    matrix = np.fft.ifft(out, axis=-1).real * (m / n)
    matrix.setflags(write=False)
    return matrix


def aperture_coverage(x: np.ndarray, y: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """Fraction (0..1) of each pixel between the lids: 0.5 + `aperture_distance`, clipped."""
    distance = aperture_distance(x, y, upper, lower)
    return clip_unit(np.add(distance, 0.5, out=distance))


def clip_unit(values: np.ndarray) -> np.ndarray:
    """`values` (an array) clipped to [0, 1] in place, NaN kept: `np.clip`'s values without its call overhead (a few
    us, which counts where a frame draws a dozen small arrays)."""
    np.maximum(values, 0.0, out=values)
    return np.minimum(values, 1.0, out=values)


def aperture_distance(x: np.ndarray, y: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """Signed distance (px, + between the lids) to the nearest lid margin or canthal vertical; x (W,) and
    y (H, 1) px give (H, W), equal-shaped x and y give pointwise values; lid polylines (K, 2) px sorted by x.

    The margins are treated as graphs y(x), which holds unless the head or camera rolls beyond ~40 deg."""
    f32 = np.float32
    d_upper = (y - np.interp(x, upper[:, 0], upper[:, 1]).astype(f32)) * _cos_slope(x, upper).astype(f32)
    d_lower = (np.interp(x, lower[:, 0], lower[:, 1]).astype(f32) - y) * _cos_slope(x, lower).astype(f32)
    d_side = np.minimum(x - upper[0, 0], upper[-1, 0] - x).astype(f32)
    return np.minimum(np.minimum(d_upper, d_lower), d_side)


def _cos_slope(x: np.ndarray, line: np.ndarray) -> np.ndarray:
    """cos(atan(dy/dx)) of the polyline `line` (K, 2), sorted by x, at abscissae x."""
    dx, dy = np.diff(line[:, 0]), np.diff(line[:, 1])
    cos = np.abs(dx) / np.maximum(np.hypot(dx, dy), 1e-12)
    return np.interp(x, (line[1:, 0] + line[:-1, 0]) / 2, cos)
