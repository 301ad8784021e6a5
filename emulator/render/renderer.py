"""Synthetic infrared frames from the ray-traced geometry: features -> 8-bit camera images with ground truth.

Model (see docs/frames.md): the geometry of each eye sample (`render_geometry.EyeOutline`: refracted
pupil outline, limbus, glints, head-fixed eyelids following gaze and blinks) is drawn in 2-D with
anti-aliased coverage (`render_draw`): dark pupil, iris, sclera, skin, optional eyelashes, glints as small
Gaussian spots; then defocus (a Gaussian blur of `blur_sigma_px`, only where something was drawn), sensor
noise and saturation:

    signal = radiance * exposure * g,     g = 10^(gain_db / 20)
    noise  = N(0, 1) * sqrt((g read_noise_dn)^2 + g k signal),    k = saturation_dn / full_well_e (DN/e-)
    pixel  = clip(round(signal + noise), 0, saturation_dn)

The normal deviates are 16-bit uniform integers (`noise.uniform16`: the raw 64-bit words of the caller's
`numpy.random.Generator`'s bit generator, four to a word, or a `noise.CounterNoise`'s draws) mapped through the
inverse normal CDF (exact quantiles, tails cut at 4.3 sigma): about five times faster than
`Generator.standard_normal`. A frame is a deterministic function of its geometry, settings and generator state (or
counter noise key).

Windows: a region of interest (`render_roi`, default 320 x 240 px centred on the pupil, kept on the
sensor) as real devices stream, or the full sensor (`render_full`, every eye of the sample). Ground truth
(`Truth`) is in full-sensor px: the pupil ellipse fitted to the ray-traced boundary and the glint centres.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.special import ndtri

from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.render import kernels
from eyehil.emulator.render.draw import Box, Levels, draw_eye
from eyehil.emulator.render.geometry import EyeOutline, aperture_distance, eye_outlines
from eyehil.emulator.render.noise import CounterNoise, Noise, uniform16
from eyehil.emulator.scene import Scene

_NORMAL_TABLE = ndtri((np.arange(65536) + 0.5) / 65536).astype(np.float32)
_SCRATCH = threading.local()  # per-thread work arrays (`_scratch`)
DEFAULT_ROI = (320, 240)


@dataclass(frozen=True)
class Appearance:
    """Radiances (DN at exposure 1, 0 dB) of the dark-pupil IR image and feature sizes."""

    pupil_dn: float = 25.0
    iris_dn: float = 95.0
    sclera_dn: float = 165.0
    skin_dn: float = 185.0
    lash_dn: float = 40.0
    glint_peak_dn: float = 1000.0  # peak above the background after the blur; saturates to a 3-4 px plateau
    glint_sigma_px: float = 0.5  # intrinsic size of the LED's reflection before defocus
    lashes: int = 0  # eyelashes drawn per eye (0: none)
    lash_length_mm: float = 8.0
    pupil_outline: str = "traced"  # "traced": the dense ray-traced outline; "ellipse": its fitted ellipse


@dataclass(frozen=True)
class Sensor:
    """Optics and sensor: defocus blur (px), exposure (relative), gain (dB), read noise (DN at 0 dB),
    full-well capacity (electrons) for shot noise, saturation level (DN)."""

    blur_sigma_px: float = 0.8
    exposure: float = 1.0
    gain_db: float = 0.0
    read_noise_dn: float = 1.5
    full_well_e: float = 10_000.0
    saturation_dn: int = 255

    def noiseless(self) -> Sensor:
        """The same optics without read or shot noise."""
        return replace(self, read_noise_dn=0.0, full_well_e=np.inf)


@dataclass(frozen=True)
class RenderSettings:
    """Everything that decides how a frame looks besides its geometry."""

    appearance: Appearance = field(default_factory=Appearance)
    sensor: Sensor = field(default_factory=Sensor)

    def levels(self) -> Levels:
        a, s = self.appearance, self.sensor
        scale = s.exposure * 10 ** (s.gain_db / 20)
        return Levels(pupil=a.pupil_dn * scale, iris=a.iris_dn * scale, sclera=a.sclera_dn * scale,
                      skin=a.skin_dn * scale, lash=a.lash_dn * scale, glint_peak=a.glint_peak_dn * scale,
                      glint_sigma_px=a.glint_sigma_px, blur_sigma_px=s.blur_sigma_px, lashes=a.lashes,
                      lash_length_mm=a.lash_length_mm, traced_pupil=a.pupil_outline == "traced")


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground truth of the n eyes drawn, full-sensor px: the pupil ellipse (centre, full axes, angle of the
    major axis in deg, from image +x toward +y), its validity and the fraction of its ray-traced boundary
    points visible (between the lids and inside the window); glints (n, L, 2), whether each centre is
    visible, and its distance (px) inside the lid aperture (a glint closer than ~3 px to a margin is
    partly hidden, so no detector can find its centre without bias)."""

    pupil_centre_px: np.ndarray
    pupil_axes_px: np.ndarray
    pupil_angle_deg: np.ndarray
    pupil_valid: np.ndarray
    pupil_visible: np.ndarray
    glint_px: np.ndarray
    glint_visible: np.ndarray
    glint_lid_px: np.ndarray


@dataclass(frozen=True, eq=False)
class Frame:
    """An 8-bit image (H, W) whose top-left pixel is sensor pixel `roi_xy`, and its ground truth (`truth`,
    computed from the drawn `outline` when first asked for: a streaming device never asks, and it cost a tenth
    of a 640 x 480 frame)."""

    image: np.ndarray
    roi_xy: tuple[int, int]
    outline: EyeOutline  # the eyes drawn, shape (n,)
    sensor_px: tuple[int, int]

    @functools.cached_property
    def truth(self) -> Truth:
        """Ground truth of the eyes drawn in this window."""
        return ground_truth(self.outline, self.roi_xy, self.image.shape[::-1])


def roi_window(centre_px: np.ndarray, size: tuple[int, int], sensor_px: tuple[int, int]) -> tuple[int, int]:
    """Top-left sensor pixel (x0, y0) of a `size` (w, h) window centred on `centre_px`, kept on the sensor."""
    (w, h), (sw, sh) = size, sensor_px
    if w > sw or h > sh:
        raise ValueError(f"region of interest {w}x{h} is larger than the sensor {sw}x{sh}")
    cx, cy = np.asarray(centre_px, float) if np.all(np.isfinite(centre_px)) else (sw / 2, sh / 2)
    return max(0, min(round(cx - w / 2), sw - w)), max(0, min(round(cy - h / 2), sh - h))


def render_features(features: Features, eyes: EyeModel, scene: Scene, rng: Noise, *,
                    index: Iterable[tuple[int, int, int, int]] | None = None, roi: tuple[int, int] | None = DEFAULT_ROI,
                    blink: float | np.ndarray = 0.0, settings: RenderSettings | None = None,
                    ) -> Iterator[tuple[tuple[int, ...], Frame]]:
    """Frames of the samples of `features` (E, S, H, T) of `eyes` in `scene`: with `roi` a region of interest
    per (e, s, h, t) in `index` (default all), with `roi=None` one full frame per (e, h, t) showing every side."""
    outline = eye_outlines(features, eyes, scene, blink=blink)
    index = np.ndindex(*features.shape) if index is None else index
    done = set()
    for e, s, h, t in index:
        if roi is not None:
            yield (e, s, h, t), render_roi(outline[e, s, h, t], rng, size=roi, settings=settings)
        elif (e, h, t) not in done:
            done.add((e, h, t))
            yield (e, h, t), render_full(outline[e, :, h, t], rng, settings=settings)


def render_roi(outline: EyeOutline, rng: Noise, *, size: tuple[int, int] = DEFAULT_ROI,
               centre_px: np.ndarray | None = None, settings: RenderSettings | None = None) -> Frame:
    """A region of interest of one eye sample (outline shape ()), centred on `centre_px` (default its pupil)."""
    if outline.shape != ():
        raise ValueError(f"render_roi draws one eye sample; got outline shape {outline.shape}")
    centre = outline.pupil_centre_px if centre_px is None else centre_px
    origin = roi_window(centre, size, outline.sensor_px)
    return render_window(outline[None], rng, origin=origin, size=size, settings=settings)


def render_full(outline: EyeOutline, rng: Noise, *, settings: RenderSettings | None = None) -> Frame:
    """The full sensor with every eye of `outline` (shape () or (n,), e.g. both sides of one fixation)."""
    batch = outline[None] if outline.shape == () else outline
    return render_window(batch, rng, origin=(0, 0), size=outline.sensor_px, settings=settings)


def render_window(outline: EyeOutline, rng: Noise, *, origin: tuple[int, int], size: tuple[int, int],
                  settings: RenderSettings | None = None) -> Frame:
    """Eyes `outline` (shape (n,)) drawn into the sensor window at `origin` (x0, y0) of `size` (w, h)."""
    settings = settings or RenderSettings()
    canvas = draw_window(outline, rng, origin=origin, size=size, settings=settings)
    image = expose_canvas(canvas, rng, settings)
    return Frame(image=image, roi_xy=origin, outline=outline, sensor_px=outline.sensor_px)


@dataclass(frozen=True, eq=False)
class Canvas:
    """What a window shows before the sensor: radiance (H, W) float32 DN after the defocus blur, flat skin outside
    `boxes` (the rows [r0, r1) and columns [c0, c1) drawn, None for an eye off the window)."""

    signal: np.ndarray
    boxes: tuple[Box | None, ...]


def draw_window(outline: EyeOutline, rng: Noise, *, origin: tuple[int, int], size: tuple[int, int],
                settings: RenderSettings) -> Canvas:
    """The noiseless canvas of eyes `outline` (n,) in the sensor window at `origin` (x0, y0) of `size` (w, h). Its
    signal is this thread's scratch array, overwritten by the next call (copy it to keep it). Draws random numbers
    from `rng` only for eyelashes (`Appearance.lashes`)."""
    levels = settings.levels()
    canvas = _scratch((size[1], size[0]))[0]
    canvas.fill(levels.skin)
    boxes = tuple(draw_eye(canvas, origin, outline[i], levels, rng) for i in range(outline.shape[0]))
    for box in boxes:
        _blur(canvas, box, settings.sensor.blur_sigma_px)
    return Canvas(canvas, boxes)


def expose_canvas(canvas: Canvas, rng: Noise, settings: RenderSettings) -> np.ndarray:
    """The image of `canvas` through the sensor (`expose`); the canvas is left as it is."""
    read, k = _noise(settings.sensor)
    signal = canvas.signal if read > 0 or k > 0 else canvas.signal.copy()  # noiseless: quantised in place
    return expose(signal, settings.sensor, rng, flat=(settings.levels().skin, list(canvas.boxes)))


def _blur(canvas: np.ndarray, box: Box | None, sigma: float) -> None:
    """Gaussian defocus on the drawn box (the canvas is flat skin elsewhere)."""
    if box is None or sigma <= 0:
        return
    r0, r1, c0, c1 = box
    region = canvas[r0:r1, c0:c1]
    cv2.GaussianBlur(region, (0, 0), sigma, dst=region, borderType=cv2.BORDER_REPLICATE)


def expose(signal: np.ndarray, sensor: Sensor, rng: Noise, *,
           flat: tuple[float, list[Box | None]] | None = None) -> np.ndarray:
    """Add read and shot noise to `signal` (float32 DN, modified in place), saturate and quantise to uint8
    (uint16 above 8 bits).

    `flat` (level, boxes): the signal is `level` everywhere outside `boxes` (canvas rows [r0, r1), columns
    [c0, c1)). Those pixels are then looked up in the table of that level's 65,536 outcomes (`flat_table`) and
    only the boxes are computed pixel by pixel: the same uniform draws and the same float32 arithmetic, so the
    same image, bit for bit; the compiled kernel (`kernels.expose_flat`) does that in one pass where it can be
    had, and leaves `signal` as it is."""
    read, k = _noise(sensor)
    if not (read > 0 or k > 0):
        return _quantise(signal, sensor)
    if flat is not None and kernels.AVAILABLE:  # the same image in one compiled pass (eyehil.emulator.render.kernels)
        level, boxes = flat
        tables = (flat_table(float(level), sensor), boxes, _NORMAL_TABLE, np.float32(k), np.float32(read * read),
                  np.float32(sensor.saturation_dn + 0.49))
        if isinstance(rng, CounterNoise):
            return kernels.expose_counter(signal, rng.key, *tables)
        return kernels.expose_flat(signal, uniform16(rng, signal.size).reshape(signal.shape), *tables)
    uniform = uniform16(rng, signal.size).reshape(signal.shape)
    if flat is None:
        return _pixels(signal, uniform, sensor, _scratch(signal.shape)[1:])
    level, boxes = flat
    out = np.take(flat_table(float(level), sensor), uniform)
    for box in boxes:
        if box is not None:
            r0, r1, c0, c1 = box
            out[r0:r1, c0:c1] = _pixels(signal[r0:r1, c0:c1].copy(), uniform[r0:r1, c0:c1], sensor)  # boxes may overlap
    return out


def _noise(sensor: Sensor) -> tuple[float, float]:
    """Read noise (DN) and shot-noise gain k (DN per DN of signal) at the sensor's gain."""
    g = 10 ** (sensor.gain_db / 20)
    return g * sensor.read_noise_dn, g * sensor.saturation_dn / sensor.full_well_e


def _pixels(signal: np.ndarray, uniform: np.ndarray, sensor: Sensor, work: list[np.ndarray] | None = None
            ) -> np.ndarray:
    """Pixels of `signal` (float32, modified in place) with the noise of the 16-bit `uniform` draws; `work`:
    two float32 arrays of the signal's shape to use (fresh ones if None)."""
    read, k = _noise(sensor)
    sigma, normal = work if work is not None else (np.empty(signal.shape, np.float32) for _ in range(2))
    np.multiply(signal, np.float32(k), out=sigma)
    np.maximum(sigma, 0.0, out=sigma)
    sigma += np.float32(read * read)
    np.sqrt(sigma, out=sigma)
    np.take(_NORMAL_TABLE, uniform, out=normal)
    sigma *= normal
    signal += sigma
    return _quantise(signal, sensor)


def _quantise(signal: np.ndarray, sensor: Sensor) -> np.ndarray:
    """Round, saturate and convert `signal` (float32 DN, modified in place)."""
    signal += 0.5
    np.clip(signal, 0.0, sensor.saturation_dn + 0.49, out=signal)
    return signal.astype(np.uint8) if sensor.saturation_dn <= 255 else signal.astype(np.uint16)


@functools.lru_cache(maxsize=16)
def flat_table(level: float, sensor: Sensor) -> np.ndarray:
    """The pixel of a signal of `level` DN for each of the 65,536 uniform draws (`_pixels` of each)."""
    return _pixels(np.full(65536, level, np.float32), np.arange(65536, dtype=np.uint16), sensor)


def _scratch(shape: tuple[int, ...]) -> list[np.ndarray]:
    """Three float32 work arrays of `shape` (canvas, noise sigma, normal deviates) kept by this thread for
    the next frame of the same size.

    Fresh multi-megabyte arrays cost a page fault per 4 kB page every frame once the allocator has handed
    the memory back; reusing them made rendering several times faster on the benchmark machine."""
    cache = _SCRATCH.__dict__.setdefault("arrays", {})
    if shape not in cache:
        if len(cache) >= 4:
            cache.clear()
        cache[shape] = [np.empty(shape, np.float32) for _ in range(3)]
    return cache[shape]


def ground_truth(outline: EyeOutline, origin: tuple[int, int], size: tuple[int, int]) -> Truth:
    """Ground truth of the eyes `outline` (n,) in the window at `origin` of `size`."""
    n, n_points = outline.shape[0], outline.pupil_points_px.shape[-2]
    seen_pupil, lid_glints = np.zeros(n), np.zeros(outline.glint_valid.shape)
    seen_glints = np.zeros(outline.glint_valid.shape, bool)
    for i in range(n):
        o = outline[i]
        inside, lid = _placed(np.concatenate([o.pupil_points_px, o.glint_px]), o, origin, size)
        seen_pupil[i] = np.mean(inside[:n_points] & (lid[:n_points] > 0.0))
        lid_glints[i] = lid[n_points:]
        seen_glints[i] = o.glint_valid & inside[n_points:] & (lid[n_points:] > 0.0)
    return Truth(pupil_centre_px=outline.pupil_centre_px, pupil_axes_px=outline.pupil_axes_px,
                 pupil_angle_deg=outline.pupil_angle_deg, pupil_valid=outline.pupil_valid,
                 pupil_visible=np.where(outline.pupil_valid, seen_pupil, 0.0), glint_px=outline.glint_px,
                 glint_visible=seen_glints, glint_lid_px=np.where(outline.glint_valid, lid_glints, np.nan))


def _placed(points: np.ndarray, o: EyeOutline, origin, size) -> tuple[np.ndarray, np.ndarray]:
    """Whether points (K, 2) px lie in the window, and their distance (px) inside the lid aperture."""
    p = np.nan_to_num(points, nan=-1e9)
    inside = np.all((p >= np.subtract(origin, 0.5)) & (p <= np.add(origin, size) - 0.5), axis=-1)
    return inside, aperture_distance(p[:, 0], p[:, 1], o.upper_lid_px, o.lower_lid_px)
