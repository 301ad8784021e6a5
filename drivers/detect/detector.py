"""Host-side feature extraction from 8-bit infrared eye images (OpenCV + numpy): pupil ellipse and glints.

Coordinates: the image is a window of the sensor whose top-left pixel is sensor pixel `roi_xy`; every
result is in full-sensor px, OpenCV convention (origin at the top-left pixel centre, x right, y down),
ellipses as in `eyehil.protocols.samples` (centre, full axes a >= b, angle of a in deg from +x toward +y).
Results are the records a device streams (`eyehil.protocols.samples.EyeFeatures`, `Features`), so everything
downstream takes either. The host sees only images: nothing here imports the emulator.

Pupil: (1) seed = the darkest pixel of the image shrunk `coarse_factor` times (area average) and box
filtered over the smallest pupil; (2) pupil level p = median of the 7 x 7 px at the seed; dark blob = the
filled outer contour (glint holes closed) of the pixels below p + `dark_margin_dn` around the seed, size
checked; iris level i = 30th percentile of a ring 4 to 5 px outside the blob (eyelid skin, brighter, may
cover much of the ring); (3) sub-pixel edge points where the level T = (p + i) / 2 is crossed between
horizontally or vertically adjacent pixels near the blob (linear interpolation: the points of a
marching-squares contour), dropping those within `glint_guard_px` of a glint, those within 2 px of a
pixel brighter than i + (i - p) / 2 (eyelid skin, whose brightness the blur mixes into the edge) and
those whose intensity gradient is more than 37 deg off the outward radial direction (the sides of
eyelashes); (4) a robust direct least-squares ellipse (`detect_ellipse`), refused when it covers less than
`min_support` or is flatter than `min_axis_ratio`. Confidence = support / (1 + (rms / 0.25 px)^2),
support = the fraction of 36 angular sectors holding inliers.

Glints and their LEDs: `detect_glints`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from eyehil.drivers.detect.ellipse import EllipseFit, robust_ellipse
from eyehil.drivers.detect.glints import PupilEllipse, disk, find_glints
from eyehil.protocols.enums import Eye, GlintFlags, PupilFlags
from eyehil.protocols.samples import EyeFeatures, Features

FAILURES = {
    "no_dark_blob": "no pupil-sized region darker than its surroundings by min_contrast_dn (eye closed?)",
    "pupil_too_small": "the dark blob is smaller than min_pupil_diameter_px",
    "pupil_too_large": "the dark blob is larger than max_pupil_diameter_px",
    "too_few_edge_points": "too few pupil edge points left (eyelid, blink, glints on the edge)",
    "ellipse_fit_failed": "no ellipse fits the edge points",
    "low_support": "the edge points cover less than min_support of the ellipse (mostly occluded)",
    "implausible_ellipse": "the ellipse is flatter than min_axis_ratio (pupil cut on two sides, e.g. blinking)",
    "glint_missing": "fewer glint candidates than LEDs",
}


@dataclass(frozen=True)
class DetectorSettings:
    """Tuning, in px and DN of the 8-bit image (see the module docstrings)."""

    min_pupil_diameter_px: float = 12.0
    max_pupil_diameter_px: float = 120.0
    coarse_factor: int = 4
    dark_margin_dn: float = 20.0
    min_contrast_dn: float = 20.0
    glint_level: float = 0.85  # of saturation
    saturation_dn: float = 255.0
    glint_search: float = 2.5  # pupil radii
    glint_max_area_px: int = 200
    glint_guard_px: int = 3
    inlier_px: float = 0.6
    refits: int = 3
    min_edge_points: int = 12
    min_support: float = 0.5
    min_axis_ratio: float = 0.5


@dataclass(frozen=True)
class Detection:
    """One eye's detected features (the record a device streams) and why they are incomplete, if so."""

    features: EyeFeatures
    failure: str | None = None
    detail: str = ""

    def __bool__(self) -> bool:
        return self.failure is None

    @property
    def pupil_px(self) -> np.ndarray:
        """Pupil centre (2,) px, NaN when no pupil was detected."""
        f = self.features
        return np.array([f.centre_x, f.centre_y]) if f.flags & PupilFlags.DETECTED else np.full(2, np.nan)

    def glints_px(self, n_leds: int) -> np.ndarray:
        """Glint centres (n_leds, 2) px by LED, NaN where not VALID."""
        out = np.full((n_leds, 2), np.nan)
        for g in self.features.glints:
            if g.flags & GlintFlags.VALID and g.led < n_leds:
                out[g.led] = (g.x, g.y)
        return out


def detect_eye(image: np.ndarray, n_leds: int, *, roi_xy: tuple[int, int] = (0, 0), eye: Eye = Eye.RIGHT,
               led_xy_mm: np.ndarray | None = None, seed_px: tuple[float, float] | None = None,
               settings: DetectorSettings | None = None) -> Detection:
    """Pupil and glints of one eye in `image` (uint8 H x W). `led_xy_mm` (n_leds, 2): world x, y (mm) of the
    LEDs, for matching (default: LED k makes the k-th glint from the left); `seed_px`: a window pixel inside
    the pupil (default: the darkest pupil-sized place)."""
    s = settings or DetectorSettings()
    img = np.ascontiguousarray(image, dtype=np.uint8)
    seed = _seeds(img, 1, s)[0] if seed_px is None else np.asarray(seed_px, float)
    pupil = _pupil(img, seed, s)
    if isinstance(pupil, str):
        return Detection(EyeFeatures(eye, PupilFlags(0), *(np.nan,) * 5, 0.0, ()), pupil, FAILURES[pupil])
    ellipse, fit = pupil
    glints, failure = find_glints(img, ellipse, n_leds, led_xy_mm, s, roi_xy)
    flags = PupilFlags.DETECTED | (PupilFlags.PARTIAL if fit.support < 0.9 else 0) | _clipped(img, ellipse)
    record = EyeFeatures(eye, flags, ellipse.centre[0] + roi_xy[0], ellipse.centre[1] + roi_xy[1], *ellipse.axes,
                         ellipse.angle, fit.support / (1.0 + (fit.rms / 0.25) ** 2), tuple(glints))
    return Detection(record, failure, FAILURES.get(failure or "", ""))


def detect_frame(image: np.ndarray, n_eyes: int, n_leds: int, *, roi_xy: tuple[int, int] = (0, 0), frame_id: int = 0,
                 led_xy_mm: np.ndarray | None = None, settings: DetectorSettings | None = None,
                 ) -> tuple[Features, list[Detection]]:
    """FEATURES of the `n_eyes` (1 or 2) darkest pupils of a frame and their detections. With two, the one at
    smaller image x is the right eye: the subject faces the camera, whose image x runs along world +x."""
    if n_eyes not in (1, 2):
        raise ValueError(f"n_eyes must be 1 or 2, got {n_eyes}")
    s = settings or DetectorSettings()
    img = np.ascontiguousarray(image, dtype=np.uint8)
    seeds = sorted(_seeds(img, n_eyes, s), key=lambda p: p[0])
    found = [detect_eye(img, n_leds, roi_xy=roi_xy, eye=e, led_xy_mm=led_xy_mm, seed_px=p, settings=s)
             for e, p in zip((Eye.RIGHT, Eye.LEFT), seeds, strict=False)]
    return Features(frame_id, tuple(d.features for d in found)), found


def _seeds(img: np.ndarray, n: int, s: DetectorSettings) -> list[np.ndarray]:
    """Window px of the `n` darkest pupil-sized places, at least half a maximum pupil diameter apart."""
    f = s.coarse_factor
    small = cv2.resize(img, (max(img.shape[1] // f, 1), max(img.shape[0] // f, 1)), interpolation=cv2.INTER_AREA)
    k = max(1, int(s.min_pupil_diameter_px / f / 2))
    smooth = cv2.blur(small, (k, k)).astype(np.float32)
    out = []
    for _ in range(n):
        _, _, (x, y), _ = cv2.minMaxLoc(smooth)
        out.append(np.array([(x + 0.5) * f - 0.5, (y + 0.5) * f - 0.5]))
        cv2.circle(smooth, (x, y), int(s.max_pupil_diameter_px / f), 1e9, -1)
    return out


def _pupil(img: np.ndarray, seed: np.ndarray, s: DetectorSettings) -> tuple[PupilEllipse, EllipseFit] | str:
    """(ellipse in window px, the fit's statistics) of the pupil around `seed`, or a failure name."""
    half = int(s.max_pupil_diameter_px / 2 + 8)
    sx, sy = (int(np.clip(v, 0, n - 1)) for v, n in zip(seed, img.shape[::-1], strict=True))
    x0, y0 = max(sx - half, 0), max(sy - half, 0)
    raw = img[y0:sy + half + 1, x0:sx + half + 1]
    crop = raw.astype(np.float32)
    sx, sy = sx - x0, sy - y0
    dark = _quantile(crop[max(sy - 3, 0):sy + 4, max(sx - 3, 0):sx + 4], 0.5)
    blob = _blob(raw, dark + s.dark_margin_dn, (sx, sy))
    if blob is None or cv2.mean(raw)[0] - dark < s.min_contrast_dn:  # a closed eye shows only skin
        return "no_dark_blob"
    diameter = 2.0 * np.sqrt(np.count_nonzero(blob) / np.pi)
    if not s.min_pupil_diameter_px <= diameter <= s.max_pupil_diameter_px:
        return "pupil_too_small" if diameter < s.min_pupil_diameter_px else "pupil_too_large"
    bx, by, bw, bh = cv2.boundingRect(blob)  # work on the blob's box plus a margin from here on
    c0, r0 = max(bx - 8, 0), max(by - 8, 0)
    crop, blob = crop[r0:by + bh + 8, c0:bx + bw + 8], blob[r0:by + bh + 8, c0:bx + bw + 8]
    x0, y0 = x0 + c0, y0 + r0
    glint = cv2.dilate(((crop >= s.glint_level * s.saturation_dn) * 255).astype(np.uint8), disk(s.glint_guard_px))
    near = cv2.dilate(blob, disk(3))
    ring = cv2.dilate(blob, disk(5)) & ~near & ~glint
    iris = _quantile(crop[ring > 0], 0.3) if np.any(ring) else dark  # eyelids only brighten the ring
    if iris - dark < s.min_contrast_dn:
        return "no_dark_blob"
    points = _edge_points(crop, 0.5 * (dark + iris), near & ~glint)
    points = _drop_near_bright(crop, points, iris + 0.5 * (iris - dark))
    points = _radial_gradient(crop, points, blob)
    fit = robust_ellipse(points, inlier_px=s.inlier_px, refits=s.refits, min_points=s.min_edge_points)
    if isinstance(fit, str):
        return fit
    if fit.support < s.min_support:
        return "low_support"
    if fit.axes[1] < s.min_axis_ratio * fit.axes[0]:
        return "implausible_ellipse"
    return PupilEllipse(fit.centre + np.array([x0, y0]), fit.axes, fit.angle), fit


def _quantile(values: np.ndarray, q: float) -> float:
    """The `q` quantile (lower order statistic) of `values`."""
    flat = values.ravel()
    k = int(q * (flat.size - 1))
    return float(np.partition(flat, k)[k])


def _blob(raw: np.ndarray, threshold: float, seed: tuple[int, int]) -> np.ndarray | None:
    """The filled outer contour (uint8 0/255) of the pixels below `threshold` holding or nearest `seed`."""
    _, mask = cv2.threshold(raw, float(np.ceil(threshold)) - 1.0, 255, cv2.THRESH_BINARY_INV)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    where = [cv2.pointPolygonTest(c, (float(seed[0]), float(seed[1])), True) for c in contours]
    filled = np.zeros(raw.shape, np.uint8)
    cv2.drawContours(filled, contours, int(np.argmax(where)), 255, -1)
    return filled


def _edge_points(crop: np.ndarray, level: float, near: np.ndarray) -> np.ndarray:
    """(N, 2) crop px where `level` is crossed between 4-neighbours both inside `near`."""
    out = []
    for axis in (1, 0):
        a = crop[:, :-1] if axis == 1 else crop[:-1, :]
        b = crop[:, 1:] if axis == 1 else crop[1:, :]
        ok = near[:, :-1] & near[:, 1:] if axis == 1 else near[:-1, :] & near[1:, :]
        rows, cols = np.nonzero(((a < level) != (b < level)) & (ok > 0))
        t = (level - a[rows, cols]) / (b[rows, cols] - a[rows, cols])
        out.append(np.stack([cols + t * axis, rows + t * (1 - axis)], axis=-1))
    return np.concatenate(out).astype(np.float32)


def _drop_near_bright(crop: np.ndarray, points: np.ndarray, limit: float, reach: int = 2) -> np.ndarray:
    """Edge points farther than `reach` px from any pixel brighter than `limit` (eyelid skin)."""
    bright = cv2.dilate((crop > limit).astype(np.uint8), disk(reach))
    ij = np.clip(np.round(points).astype(int), 0, np.array(crop.shape[::-1]) - 1)
    return points[bright[ij[:, 1], ij[:, 0]] == 0]


def _radial_gradient(crop: np.ndarray, points: np.ndarray, blob: np.ndarray, min_cos: float = 0.8) -> np.ndarray:
    """Edge points whose intensity gradient (central differences at the nearest pixel) points away from the
    blob's centroid within acos(min_cos): the sides of eyelashes across the edge run radially and fail."""
    m = cv2.moments(blob, binaryImage=True)
    radial = points - np.array([m["m10"], m["m01"]]) / max(m["m00"], 1.0)
    h, w = crop.shape
    i = np.clip(np.round(points[:, 1]).astype(int), 1, h - 2)
    j = np.clip(np.round(points[:, 0]).astype(int), 1, w - 2)
    gx, gy = crop[i, j + 1] - crop[i, j - 1], crop[i + 1, j] - crop[i - 1, j]
    dot = gx * radial[:, 0] + gy * radial[:, 1]
    return points[dot >= min_cos * np.hypot(gx, gy) * np.hypot(radial[:, 0], radial[:, 1])]


def _clipped(img: np.ndarray, p: PupilEllipse) -> PupilFlags:
    """CLIPPED when the ellipse's bounding circle crosses the window border."""
    r = p.axes[0] / 2
    h, w = img.shape
    inside = r <= p.centre[0] <= w - 1 - r and r <= p.centre[1] <= h - 1 - r
    return PupilFlags(0) if inside else PupilFlags.CLIPPED
