"""The forward model: (eyes, scene, targets or poses, head positions) -> Features.

Batched over eyes x sides x head positions x targets; no Python loop over fixations. Pipeline per
chunk of eyes (a chunk keeps memory bounded; `progress` is told after each):

1. the line of sight of each eye (fixed to the eye; `fixation.line_of_sight`);
2. targets, camera and LEDs in each head position's frame, relative to each eye's apex;
3. the pose that fixates each target (`fixation.solve_fixation`, Listing's law) or the given pose;
4. camera and LEDs into the eye-local (unrotated) frame, where the cornea is a conic about z (or a
   biconic for eyes that are not `rotationally_symmetric`: those are traced in chunks of their own, so a
   symmetric eye gives bit for bit the features of the published model whatever it is batched with);
5. glints (`optics.glint`) and the apparent pupil boundary (`optics.pupil`, 30 points by default);
6. back to the scene frame, camera projection, least-squares ellipse fit of the pupil image.

Features arrays have shape (E eyes, S sides, H head positions, T targets, ...); 3-D quantities are in
the scene frame (mm), image quantities in pixels (OpenCV convention), angles in degrees.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.surfaces import cornea_apex, cornea_centre, cornea_optics, pupil_centre, stop_ellipse
from eyehil.emulator.features import Features, empty_features
from eyehil.emulator.fixation import LineOfSight, eye_centres, line_of_sight, listing_torsion, posed, solve_fixation
from eyehil.emulator.optics.ellipse import fit_ellipse
from eyehil.emulator.optics.glint import solve_glints
from eyehil.emulator.optics.pupil import pupil_boundary, solve_exit_points
from eyehil.emulator.optics.rays import affine
from eyehil.emulator.scene import HeadPose, Scene

POINTS_PER_CHUNK = 120_000


@dataclass(frozen=True)
class Poses:
    """Explicit eye poses (deg), shape (P,) each; torsion None means Listing's law."""

    azimuth: np.ndarray
    elevation: np.ndarray
    torsion: np.ndarray | None = None


@dataclass(frozen=True)
class Placement:
    """Where the eye sits: head positions (head -> scene rotation (H, 3, 3), translation (H, 3)) and the
    eye's apex in the head frame (3,)."""

    rotation: np.ndarray
    translation: np.ndarray
    apex: np.ndarray

    @classmethod
    def of(cls, heads: tuple[HeadPose, ...], apex: np.ndarray) -> Placement:
        return cls(np.stack([h.rotation for h in heads]), np.stack([h.translation for h in heads]), apex)

    def scene_to_eye(self, p: np.ndarray) -> np.ndarray:
        """Scene points (..., 3) -> (H, ..., 3) in the eye frame of each head position."""
        shift = self.translation.reshape((-1,) + (1,) * (p.ndim - 1) + (3,))
        rot = self.rotation.reshape((-1,) + (1,) * (p.ndim - 1) + (3, 3))
        return np.einsum("h...j,h...jk->h...k", p[None] - shift, rot) - self.apex

    def eye_to_scene(self, p: np.ndarray) -> np.ndarray:
        """Eye-frame points (E, H, T, N, 3) -> scene frame."""
        return np.einsum("hjk,ehtnk->ehtnj", self.rotation, p + self.apex) + self.translation[:, None, None, :]

    def posed_to_scene(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The eye pose (eye-local -> eye frame: p -> a p + b, a (E, H, T, 3, 3), b (E, H, T, 3)) composed with
        `eye_to_scene`: the matrices m and offsets o of eye-local -> scene, p -> m p + o (`rays.affine`)."""
        m = np.einsum("hjk,ehtki->ehtji", self.rotation, a)
        return m, np.einsum("hjk,ehtk->ehtj", self.rotation, b + self.apex) + self.translation[:, None, :]


def simulate(
    eyes: EyeModel,
    scene: Scene,
    *,
    targets: np.ndarray | None = None,
    poses: Poses | None = None,
    head_positions: tuple[HeadPose, ...] | None = None,
    media: Media | None = None,
    n_pupil_points: int = 30,
    progress: Callable[[int], None] | None = None,
    pupil_solver: str = "secant",
) -> Features:
    """Features of `eyes` (a batch or one eye; anatomy as right eyes, `scene.sides` says which eyes the
    subject uses) fixating `targets` (T, 3, scene frame mm; default the scene's grid) or held at `poses`.
    `pupil_solver`: `optics.pupil.solve_exit_points`' method ("secant", or the earlier "newton")."""
    if targets is not None and poses is not None:
        raise ValueError("give targets or poses, not both")
    eyes = eyes.as_batch()
    media = media or Media.named(scene.media, scene.wavelength_nm)
    heads = tuple(head_positions or scene.head_positions)
    if poses is None:
        targets = scene.targets() if targets is None else _checked_targets(targets)
        n_targets = len(targets)
    else:
        n_targets = len(np.atleast_1d(poses.azimuth))
    out = empty_features(len(eyes), scene, heads, n_targets, n_pupil_points, targets, media.label)
    step = max(1, POINTS_PER_CHUNK // (len(scene.sides) * len(heads) * n_targets * n_pupil_points))
    symmetric = eyes.rotationally_symmetric
    for group in (np.flatnonzero(symmetric), np.flatnonzero(~symmetric)):
        for start in range(0, len(group), step):
            chunk = group[start:start + step]
            rows = slice(chunk[0], chunk[-1] + 1) if chunk[-1] - chunk[0] + 1 == len(chunk) else chunk
            for s, side in enumerate(scene.sides):
                place = Placement.of(heads, scene.apex(side))
                result = _simulate_eyes(eyes[rows].with_laterality(side), scene, place, targets, poses, media,
                                        n_pupil_points, pupil_solver)
                for name, value in result.items():
                    out.arrays[name][rows, s] = value
            if progress is not None:
                progress(len(chunk))
    return out


def _checked_targets(targets: np.ndarray) -> np.ndarray:
    t = np.asarray(targets, dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(t)):
        raise ValueError("targets must be finite (mm)")
    if np.any(t[:, 2] <= 0):
        raise ValueError("targets must lie in front of the eyes (z > 0 mm in the scene frame)")
    return t


def _poses(eye, place, los, centres, targets, poses) -> dict[str, np.ndarray]:
    if poses is None:
        pad = (slice(None), None, None)
        los_b = LineOfSight(los.origin[pad], los.direction[pad], los.fovea[pad], los.valid[pad])
        pose = solve_fixation(centres, los_b, place.scene_to_eye(targets)[None])
        az, el, tor, res, ok = pose.azimuth, pose.elevation, pose.torsion, pose.residual_mm, pose.valid
    else:
        shape = (len(eye), len(place.rotation), len(np.atleast_1d(poses.azimuth)))
        az, el = (np.broadcast_to(np.atleast_1d(v), shape) for v in (poses.azimuth, poses.elevation))
        tor = listing_torsion(az, el) if poses.torsion is None else np.broadcast_to(np.atleast_1d(poses.torsion), shape)
        res, ok = np.zeros(shape), np.ones(shape, dtype=bool)
    return {"azimuth_deg": az, "elevation_deg": el, "torsion_deg": tor, "fixation_residual_mm": res,
            "fixation_valid": ok & los.valid[:, None, None]}


def _simulate_eyes(eye: EyeModel, scene: Scene, place: Placement, targets, poses, media, n_points,
                   pupil_solver: str = "secant") -> dict:
    los = line_of_sight(eye, media)
    centres = tuple(c[:, None, None, :] for c in eye_centres(eye))
    out = _poses(eye, place, los, centres, targets, poses)
    a, b = posed(centres, out["azimuth_deg"], out["elevation_deg"], out["torsion_deg"])

    def to_local(p_eye: np.ndarray) -> np.ndarray:  # (E, H, T, N, 3) eye frame -> eye-local (A^T (p - b))
        return np.einsum("ehtji,ehtnj->ehtni", a, p_eye - b[..., None, :])

    local_to_scene = place.posed_to_scene(a, b)

    def to_scene(p_local: np.ndarray) -> np.ndarray:  # (E, H, T, N, 3) eye-local -> scene
        return affine(*local_to_scene, p_local)

    shape = a.shape[:3]
    camera = to_local(np.broadcast_to(place.scene_to_eye(scene.camera.position)[None, :, None, None], (*shape, 1, 3)))
    leds = to_local(np.broadcast_to(place.scene_to_eye(scene.leds)[None, :, None], shape + scene.leds.shape))
    optics = cornea_optics(eye, media, 3)
    glints = solve_glints(optics.anterior, leds, camera)
    if np.all(eye.rotationally_symmetric):
        boundary = pupil_boundary(pupil_centre(eye)[..., :2], eye.pupil_radius, -eye.stop_depth, n_points)
    else:
        eccentricity, axis = stop_ellipse(eye)
        boundary = pupil_boundary(pupil_centre(eye)[..., :2], eye.pupil_radius, -eye.stop_depth, n_points,
                                  eccentricity=eccentricity, axis_deg=axis)
    exits = solve_exit_points(optics, camera, boundary[:, None, None], centre=pupil_centre(eye)[:, None, None, None],
                              solver=pupil_solver)
    out.update(_image_features(scene, to_scene, glints, exits))
    out.update(_ground_truth(eye, los, a, place, to_scene))
    return out


def _image_features(scene: Scene, to_scene, glints, exits) -> dict[str, np.ndarray]:
    """Pixels of glints and pupil points, the pupil ellipse, and whether everything falls on the sensor.

    Points off the sensor keep their (extrapolated) pixels, as in gkaModelEye and the published study;
    `in_image` says whether a real sensor would have seen them."""
    cam = scene.camera
    glint_px, front = cam.project(to_scene(glints.point))
    glint_ok = glints.valid & front
    pupil_px, front = cam.project(to_scene(exits.point))
    point_ok = exits.valid & front
    ellipse = fit_ellipse(pupil_px, point_ok)
    on_sensor = np.all(cam.in_image(glint_px) | ~glint_ok, axis=-1) & np.all(cam.in_image(pupil_px) | ~point_ok, -1)
    return {
        "glint_px": np.where(glint_ok[..., None], glint_px, np.nan), "glint_valid": glint_ok,
        "glint_residual_mm": glints.residual_mm,
        "pupil_points_px": np.where(point_ok[..., None], pupil_px, np.nan), "pupil_points_valid": point_ok,
        "pupil_residual_mm": np.max(np.where(point_ok, exits.residual_mm, 0.0), axis=-1),
        "pupil_centre_px": np.where(ellipse.valid[..., None], ellipse.centre, np.nan),
        "pupil_axes_px": np.where(ellipse.valid[..., None], ellipse.axes, np.nan),
        "pupil_angle_deg": np.where(ellipse.valid, ellipse.angle_deg, np.nan), "pupil_valid": ellipse.valid,
        "in_image": on_sensor,
    }


def _ground_truth(eye: EyeModel, los: LineOfSight, a: np.ndarray, place: Placement, to_scene) -> dict:
    apex = np.zeros((len(eye), 3)) if np.all(eye.rotationally_symmetric) else cornea_apex(eye)
    local = np.stack([cornea_centre(eye), pupil_centre(eye), los.origin, apex, los.fovea], axis=1)
    shape = a.shape[:3]
    points = to_scene(np.broadcast_to(local[:, None, None], shape + local.shape[1:]))
    axes = np.stack([np.broadcast_to([0.0, 0.0, 1.0], (len(eye), 3)), los.direction], axis=1)
    dirs = np.einsum("hjk,ehtkl,eml->ehtmj", place.rotation, a, axes)
    names = ("cornea_centre", "pupil_centre", "los_origin", "apex", "fovea")
    out = {name: points[..., i, :] for i, name in enumerate(names)}
    out["optic_axis"], out["visual_axis"] = dirs[..., 0, :], dirs[..., 1, :]
    return out
