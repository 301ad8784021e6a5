"""The 3-D eye model of the ZeroMQ facade: `pupil.<id>.3d` datums and the 3-D parts of `gaze.3d.*`.

Pupil Capture fits an eyeball model to the eye images (pye3d); this tracker knows its eyes, so the model is
taken from the simulated eye: the eyeball sphere's centre is the mean of the eye's azimuth and elevation
rotation centres (`eyehil.emulator.fixation.eye_centres`, head pose applied), and the pupil lies on a sphere around
it of radius |pupil plane centre (anterior apex - (CCT + ACD) along the eye's axis) - sphere centre|. Each
exposure's pupil is placed where the camera ray through its image centre meets that sphere (the nearer hit;
corneal refraction is ignored, as a model-based tracker without refraction correction would), and the
`circle_3d` normal points from the sphere centre to it. ``diameter_3d`` is the anatomical pupil's diameter.

Frames: Pupil's "eye camera" is the scene camera here, so `sphere`, `circle_3d` and `theta` / `phi` are in the
camera frame (mm; x right, y down in the image, z forward along the optical axis). `gaze.3d` quantities are in
the scene frame (mm; Pupil's "world" is the screen's scene): eye centres, gaze normals from an eye centre to
the gaze point, `gaze_point_3d` the gaze point on the screen. Pupil's angles: theta = arccos(n_y),
phi = atan2(n_z, n_x) of the circle normal n (camera frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from eyehil.emulator.device.solver import FeatureSolver
from eyehil.emulator.fixation import eye_centres


@dataclass(frozen=True)
class EyeModel3d:
    """Per tracked eye (solver order): sphere centres (E, 3) scene mm, pupil sphere radii (E,) mm, the
    pupil diameter (mm), and the camera (K, R world->camera, o)."""

    centres: np.ndarray
    radii: np.ndarray
    pupil_mm: float
    K: np.ndarray
    R: np.ndarray
    o: np.ndarray

    @classmethod
    def of(cls, solver: FeatureSolver) -> EyeModel3d:
        scene, eye, head = solver.scene, solver.eye, solver.head
        centres, radii = [], []
        for side in scene.sides:
            az, el = eye_centres(eye)
            c_eye = 0.5 * (np.asarray(az, float).reshape(3) + np.asarray(el, float).reshape(3))
            if side == "left":
                c_eye[0] *= -1.0  # the published vectors are a right eye's (x nasal)
            pupil_eye = np.array([0.0, 0.0, -float(np.asarray(eye.cct + eye.acd).reshape(-1)[0])])
            apex = scene.apex(side)
            centres.append(head.rotation @ (apex + c_eye) + head.translation)
            radii.append(float(np.linalg.norm(pupil_eye - c_eye)))
        cam = scene.camera
        return cls(np.array(centres), np.array(radii), 2.0 * float(np.asarray(eye.pupil_radius).reshape(-1)[0]),
                   np.asarray(cam.matrix, float), np.asarray(cam.rotation, float), np.asarray(cam.position, float))

    def pupils(self, centre_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pupil centres (N, E, 3) scene mm and unit normals (N, E, 3) scene frame, from image centres
        (N, E, 2) px (NaN where the ray misses the sphere or the centre is NaN)."""
        uv1 = np.concatenate([centre_px, np.ones((*centre_px.shape[:-1], 1))], axis=-1)
        d = uv1 @ self._rays  # world directions (rows: R^T K^-1 uv1)
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        oc = self.o - self.centres  # (E, 3)
        b = np.sum(d * oc, axis=-1)
        c = np.sum(oc * oc, axis=-1) - self.radii**2
        disc = b**2 - c
        t = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
        p = self.o + t[..., None] * d
        n = (p - self.centres) / self.radii[:, None]
        return p, n

    @cached_property
    def _rays(self) -> np.ndarray:
        """(K^-1)^T R: image (u, v, 1) rows to scene directions (computed once; the facade asks 1,000 times a s)."""
        return np.linalg.inv(self.K).T @ self.R

    @cached_property
    def spheres(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The eyeball spheres as the camera sees them: centres (E, 3) camera frame mm, centres (E, 2) full-sensor
        px and projected diameters (E,) px."""
        sphere_cam = self.to_camera(self.centres)
        proj = sphere_cam @ self.K.T
        return sphere_cam, proj[:, :2] / proj[:, 2:3], 2.0 * self.radii * self.K[0, 0] / sphere_cam[:, 2]

    def to_camera(self, v: np.ndarray, point: bool = True) -> np.ndarray:
        """Scene points (or directions, `point` False) (..., 3) in the camera frame."""
        return ((v - self.o) if point else v) @ self.R.T


def angles(normal_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pupil's (theta, phi) rad of camera-frame unit normals (..., 3)."""
    return np.arccos(np.clip(normal_cam[..., 1], -1, 1)), np.arctan2(normal_cam[..., 2], normal_cam[..., 0])


def pupil_3d_datums(exp_centre_px: np.ndarray, found: np.ndarray, model: EyeModel3d, windows: list,
                    pupil_2d: list[list[dict]]) -> list[list[dict]]:
    """`pupil.<id>.3d` datums (per exposure, per eye) from the exposures' full-sensor pupil centres (N, E, 2),
    detection (N, E) and their 2-D datums (whose image fields they share)."""
    p, n = model.pupils(np.where(found[..., None], exp_centre_px, np.nan))
    ok = found & np.isfinite(n).all(-1)
    sphere_cam, sphere_px, sphere_axes = model.spheres  # (E, 3), (E, 2) full sensor, (E,)
    circle_cam, normal_cam = model.to_camera(p), model.to_camera(n, point=False)
    theta, phi = angles(normal_cam)
    # Python numbers, converted once for the batch (zeros where the pupil was not found)
    okv = ok[..., None]
    circle_l, normal_l = np.where(okv, circle_cam, 0.0).tolist(), np.where(okv, normal_cam, 0.0).tolist()
    theta_l, phi_l, ok_l = np.where(ok, theta, 0.0).tolist(), np.where(ok, phi, 0.0).tolist(), ok.tolist()
    spheres = [(sphere_cam[e].tolist(), float(model.radii[e]), (sphere_px[e] - windows[e].origin).tolist(),
                float(sphere_axes[e])) for e in range(len(windows))]
    radius, diameter = model.pupil_mm / 2, model.pupil_mm
    out = []
    for i, datums in enumerate(pupil_2d):
        row = []
        for e, d2 in enumerate(datums):
            good = ok_l[i][e]
            row.append(pupil_3d_datum(d2, *spheres[e], circle_l[i][e], normal_l[i][e], radius if good else 0.0,
                                      diameter if good else 0.0, theta_l[i][e], phi_l[i][e],
                                      d2["confidence"] if good else 0.0))
        out.append(row)
    return out


def gaze_3d_datum(eye_ids: list[int], timestamp: float, norm_pos: np.ndarray, confidence: float,
                  base_data: list[dict], centres: list[np.ndarray], gaze_point: np.ndarray) -> dict:
    """A `gaze.3d.<ids>.` datum: binocular (eye_centers_3d, gaze_normals_3d keyed "0" / "1") or monocular
    (eye_center_3d, gaze_normal_3d); gaze_point_3d; scene mm (see the module docstring)."""
    ids = "".join(str(i) for i in sorted(eye_ids))
    normals = [(gaze_point - c) / np.linalg.norm(gaze_point - c) for c in centres]
    datum = {"topic": f"gaze.3d.{ids}.", "norm_pos": [float(norm_pos[0]), float(norm_pos[1])],
             "confidence": float(confidence), "timestamp": float(timestamp), "base_data": base_data,
             "gaze_point_3d": [float(v) for v in gaze_point]}
    if len(eye_ids) == 2:
        datum["eye_centers_3d"] = {str(e): [float(v) for v in c] for e, c in zip(eye_ids, centres, strict=True)}
        datum["gaze_normals_3d"] = {str(e): [float(v) for v in n] for e, n in zip(eye_ids, normals, strict=True)}
    else:
        datum["eye_center_3d"] = [float(v) for v in centres[0]]
        datum["gaze_normal_3d"] = [float(v) for v in normals[0]]
    return datum


def surface_datum(name: str, timestamp: float, gaze: list[dict]) -> dict:
    """A `surfaces.<name>` datum for the screen (the surface IS the screen, so gaze on it has the gaze's own
    norm_pos; `on_surf` when inside [0, 1]^2), as Pupil's surface tracker publishes it."""
    on = []
    for g in gaze:
        x, y = g["norm_pos"]
        on.append({"topic": g["topic"] + "_on_surface", "norm_pos": [x, y], "confidence": g["confidence"],
                   "on_surf": bool(0.0 <= x <= 1.0 and 0.0 <= y <= 1.0), "base_data": [g["topic"], g["timestamp"]],
                   "timestamp": g["timestamp"]})
    return {"topic": f"surfaces.{name}", "name": name, "uid": f"eyehil-screen-{name}", "timestamp": float(timestamp),
            "gaze_on_surfaces": on, "fixations_on_surfaces": []}


def pupil_3d_datum(d2: dict, sphere_cam: np.ndarray, sphere_radius: float, sphere_px: np.ndarray,
                   sphere_axis_px: float, circle_cam: np.ndarray, normal_cam: np.ndarray, circle_radius: float,
                   diameter_3d: float, theta: float, phi: float, confidence: float) -> dict:
    """A `pupil.<id>.3d` datum: the 2-D datum's image fields and pye3d's model fields."""
    return {**{k: d2[k] for k in ("id", "timestamp", "norm_pos", "diameter", "ellipse")},
            "topic": f"pupil.{d2['id']}.3d", "method": "3d c++", "confidence": float(confidence),
            "sphere": {"center": [float(v) for v in sphere_cam], "radius": sphere_radius},
            "projected_sphere": {"center": [float(v) for v in sphere_px], "axes": [sphere_axis_px] * 2, "angle": 0.0},
            "circle_3d": {"center": [float(v) for v in circle_cam], "normal": [float(v) for v in normal_cam],
                          "radius": circle_radius},
            "diameter_3d": diameter_3d, "model_confidence": 1.0, "theta": theta, "phi": phi,
            "location": list(d2["ellipse"]["center"])}
