"""Pinhole camera: world (head-frame) points in mm to image pixels (OpenCV convention).

Camera frame: x right in the image, y down, z along the viewing direction. Orientation from named
angles: unrotated, the camera looks along -z of the world (toward the subject) with image x along
world +x (the subject's left appears on the image's right); then `roll_deg` about the viewing axis,
`pitch_deg` about world x (positive tilts the view up, +y), `yaw_deg` about world y (positive turns the
view toward +x). Projection: Xc = R (X - o), x = Xc / zc, optional radial distortion
x' = x (1 + k1 r^2 + k2 r^4), pixel = (fx x' + cx, fy y' + cy), origin at the top-left pixel centre.

Known answer: a camera at o = (0, 0, 600) with no rotation and K = diag(1000, 1000, 1) + (320, 240)
projects the world origin to pixel (320, 240) and (10, 0, 0) to (320 + 1000 * 10 / 600, 240).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

BASE_ORIENTATION = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]).T  # columns: camera axes


def _rot(axis: int, angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def orientation(pitch_deg: float = 0.0, yaw_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """World -> camera rotation matrix R for the named angles (see the module docstring)."""
    yaw, pitch, roll = _rot(1, -np.radians(yaw_deg)), _rot(0, np.radians(pitch_deg)), _rot(2, np.radians(roll_deg))
    camera_to_world = yaw @ pitch @ BASE_ORIENTATION @ roll
    return camera_to_world.T


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """Intrinsics (px), pose (world mm) and image size; see the module docstring."""

    focal_px: tuple[float, float]
    principal_px: tuple[float, float]
    resolution_px: tuple[int, int]
    position: np.ndarray  # nodal point, world mm
    rotation: np.ndarray  # world -> camera, (3, 3)
    distortion: tuple[float, float] = (0.0, 0.0)  # radial k1, k2
    pose_deg: dict[str, float] = field(default_factory=dict)  # the named angles it was built from

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", np.asarray(self.position, dtype=float))
        object.__setattr__(self, "rotation", np.asarray(self.rotation, dtype=float))
        if min(self.focal_px) <= 0:
            raise ValueError("camera focal length must be > 0 px")
        if min(self.resolution_px) <= 0:
            raise ValueError("camera resolution must be > 0 px")
        if self.position.shape != (3,) or self.rotation.shape != (3, 3):
            raise ValueError("camera position must be (3,) and rotation (3, 3)")
        if not np.allclose(self.rotation @ self.rotation.T, np.eye(3), atol=1e-9):
            raise ValueError("camera rotation must be orthonormal")

    @classmethod
    def from_angles(cls, *, position: np.ndarray, pitch_deg: float = 0.0, yaw_deg: float = 0.0,
                    roll_deg: float = 0.0, **kwargs: object) -> PinholeCamera:
        pose = {"pitch_deg": pitch_deg, "yaw_deg": yaw_deg, "roll_deg": roll_deg}
        return cls(position=position, rotation=orientation(pitch_deg, yaw_deg, roll_deg), pose_deg=pose,
                   **kwargs)  # type: ignore[arg-type]

    @property
    def matrix(self) -> np.ndarray:
        """The intrinsic matrix K (3, 3), px."""
        (fx, fy), (cx, cy) = self.focal_px, self.principal_px
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in the camera frame (mm)."""
        return (points - self.position) @ self.rotation.T

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (..., 2) of world points (..., 3) and whether each lies in front of the camera."""
        pc = self.to_camera(points)
        in_front = pc[..., 2] > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = pc[..., :2] / pc[..., 2:3]
        k1, k2 = self.distortion
        if k1 or k2:
            r2 = np.sum(xy**2, axis=-1, keepdims=True)
            xy = xy * (1.0 + k1 * r2 + k2 * r2**2)
        pixels = xy * np.asarray(self.focal_px) + np.asarray(self.principal_px)
        return pixels, in_front

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Whether pixels (..., 2) fall on the sensor."""
        w, h = self.resolution_px
        return (pixels[..., 0] >= -0.5) & (pixels[..., 0] <= w - 0.5) & (pixels[..., 1] >= -0.5) & (
            pixels[..., 1] <= h - 0.5
        )
