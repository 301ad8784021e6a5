"""What a host knows about its tracker: camera, LEDs and screen in a fixed WORLD frame.

WORLD frame (mm): right-handed; x to the subject's left, y up, z from the subject toward the screen
and the camera. The subject's eyes are near z = 0; the screen is a plane ahead at z > 0.

CAMERA frame: OpenCV convention, x right in the image, y down in the image, z along the viewing
direction. A world point X maps to camera coordinates X_c = R (X - o), with R the world -> camera
rotation and o the camera nodal point (world, mm); its image is (u, v, 1)^T ~ K X_c, with K the
intrinsic matrix (px). Pixel coordinates follow OpenCV: origin at the top-left pixel centre.

SCREEN coordinates (mm): xy on the screen plane measured from the screen centre along the screen's
unit axes `x_axis` and `y_axis` (world vectors). The default axes are world +x (the subject's left)
and world +y (up), so for a fronto-parallel screen screen-mm coordinates are world (x, y) offsets
from the centre. This is NOT the viewer's "x to the right" convention: a target on the subject's
right has negative screen x.

Everything here is pure numpy, batched over leading dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_ORTHO_TOL = 1e-9


def _frozen_array(value: object, shape: tuple[int, ...], name: str) -> np.ndarray:
    """A read-only float64 copy of `value`, checked to have `shape` and finite entries."""
    arr = np.array(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    arr.flags.writeable = False
    return arr


def _unit(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera: intrinsics `K` (px), rotation `R` (world -> camera), nodal point `o` (world, mm).

    `image_size` is (width, height) in px.
    """

    K: np.ndarray
    R: np.ndarray
    o: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self) -> None:
        K = _frozen_array(self.K, (3, 3), "K")
        R = _frozen_array(self.R, (3, 3), "R")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0:
            raise ValueError("K must be upper triangular with positive focal lengths and last row (0, 0, 1)")
        if not np.allclose(R @ R.T, np.eye(3), atol=_ORTHO_TOL) or np.linalg.det(R) <= 0:
            raise ValueError("R must be a proper rotation matrix (orthonormal, det +1)")
        width, height = self.image_size
        if int(width) <= 0 or int(height) <= 0:
            raise ValueError("image_size must be positive (width, height) in px")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "o", _frozen_array(self.o, (3,), "o"))
        object.__setattr__(self, "image_size", (int(width), int(height)))

    @classmethod
    def look_at(
        cls,
        o: np.ndarray,
        target: np.ndarray,
        K: np.ndarray,
        image_size: tuple[int, int],
        image_x: np.ndarray | tuple[float, float, float] = (1.0, 0.0, 0.0),
    ) -> Camera:
        """A camera at `o` (world, mm) whose optical axis points at `target` (world, mm).

        The image x axis is `image_x` (world) made orthogonal to the optical axis; camera
        y = z x x completes the right-handed OpenCV frame (y down in the image).
        """
        z = _unit(np.asarray(target, float) - np.asarray(o, float))
        x = np.asarray(image_x, float) - np.dot(image_x, z) * z
        x = _unit(x)
        return cls(K=K, R=np.stack([x, np.cross(z, x), z]), o=o, image_size=image_size)

    def ray_directions(self, pixels: np.ndarray) -> np.ndarray:
        """Unit world directions (..., 3) from the nodal point through `pixels` (..., 2) px.

        d = R^T K^-1 (u, v, 1)^T, normalised; it points into the scene (camera z > 0).
        """
        px = np.asarray(pixels, float)
        homog = np.concatenate([px, np.ones((*px.shape[:-1], 1))], axis=-1)
        d_cam = np.linalg.solve(self.K, homog[..., None])[..., 0]
        return _unit(d_cam @ self.R)

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """Camera-frame coordinates (..., 3) mm of world points (..., 3) mm: X_c = R (X - o)."""
        return (np.asarray(points, float) - self.o) @ self.R.T

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) of world points (..., 3) mm: (u, v, 1) ~ K R (X - o).

        Points behind the camera (camera z <= 0) give NaN.
        """
        xc = self.to_camera(points)
        z = xc[..., 2:3]
        uvw = xc @ self.K.T
        return np.where(z > 0, uvw[..., :2] / np.where(z > 0, z, 1.0), np.nan)


@dataclass(frozen=True, eq=False)
class Screen:
    """A flat rectangular screen facing the subject.

    `centre` (world, mm); `x_axis`, `y_axis` orthonormal world unit vectors spanning the plane
    (defaults: world +x = subject's left, world +y = up); `size_mm` = (width, height) along them.
    The plane normal `normal` = x_axis x y_axis (world +z for the defaults: away from the subject).
    """

    centre: np.ndarray
    size_mm: tuple[float, float]
    x_axis: np.ndarray = (1.0, 0.0, 0.0)
    y_axis: np.ndarray = (0.0, 1.0, 0.0)

    def __post_init__(self) -> None:
        x_axis = _frozen_array(self.x_axis, (3,), "x_axis")
        y_axis = _frozen_array(self.y_axis, (3,), "y_axis")
        gram = np.array([[x_axis @ x_axis, x_axis @ y_axis], [x_axis @ y_axis, y_axis @ y_axis]])
        if not np.allclose(gram, np.eye(2), atol=_ORTHO_TOL):
            raise ValueError("x_axis and y_axis must be orthonormal")
        width, height = (float(s) for s in self.size_mm)
        if not (width > 0 and height > 0):
            raise ValueError("size_mm must be positive (width, height)")
        object.__setattr__(self, "centre", _frozen_array(self.centre, (3,), "centre"))
        object.__setattr__(self, "x_axis", x_axis)
        object.__setattr__(self, "y_axis", y_axis)
        object.__setattr__(self, "size_mm", (width, height))

    @property
    def normal(self) -> np.ndarray:
        """Unit plane normal x_axis x y_axis (world)."""
        return np.cross(self.x_axis, self.y_axis)

    def to_world(self, xy_mm: np.ndarray) -> np.ndarray:
        """World points (..., 3) mm of screen coordinates (..., 2) mm: centre + x e_x + y e_y."""
        xy = np.asarray(xy_mm, float)
        return self.centre + xy[..., :1] * self.x_axis + xy[..., 1:2] * self.y_axis

    def to_screen(self, points: np.ndarray) -> np.ndarray:
        """Screen coordinates (..., 2) mm of world points (..., 3) mm (orthogonal projection)."""
        rel = np.asarray(points, float) - self.centre
        return np.stack([rel @ self.x_axis, rel @ self.y_axis], axis=-1)

    def intersect(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Screen coordinates (..., 2) mm where the lines origin + k direction meet the plane.

        k = n.(centre - origin) / n.direction; lines parallel to the plane or meeting it behind
        the origin (k <= 0) give NaN.
        """
        origin = np.asarray(origin, float)
        direction = np.asarray(direction, float)
        denom = direction @ self.normal
        safe = np.where(np.abs(denom) > 1e-12, denom, np.nan)
        k = ((self.centre - origin) @ self.normal) / safe
        k = np.where(k > 0, k, np.nan)
        return self.to_screen(origin + k[..., None] * direction)

    def grid(self, columns: int, rows: int) -> np.ndarray:
        """Targets (rows, columns, 2) mm spanning the whole screen, edges included.

        Row 0 is the top row (largest y); column 0 is on the +x_axis edge.
        """
        width, height = self.size_mm
        xs = np.linspace(width / 2, -width / 2, columns)
        ys = np.linspace(height / 2, -height / 2, rows)
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx, gy], axis=-1)


@dataclass(frozen=True, eq=False)
class TrackerGeometry:
    """The host's model of its tracker: one camera, `leds` (n_leds, 3) world mm, one screen."""

    camera: Camera
    leds: np.ndarray
    screen: Screen

    def __post_init__(self) -> None:
        leds = np.array(self.leds, dtype=float)
        if leds.ndim != 2 or leds.shape[1] != 3 or leds.shape[0] < 1:
            raise ValueError(f"leds must have shape (n_leds >= 1, 3), got {leds.shape}")
        object.__setattr__(self, "leds", _frozen_array(leds, leds.shape, "leds"))

    @property
    def n_leds(self) -> int:
        """Number of LEDs (glints per eye)."""
        return int(self.leds.shape[0])
