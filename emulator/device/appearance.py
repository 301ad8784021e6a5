"""What the renderer needs of an exposure, carried as extra channels of the subject's features.

`eyehil.emulator.render.renderer` draws an eye from its image-plane geometry (`render_geometry.EyeOutline`): the
ray-traced pupil outline, the limbus, the glints and the eyelid margins. The device's subject computes
features per gaze point (`eyehil.emulator.device.solver`: exact at fixations, interpolated in a grid during
saccades and pursuits); `AppearanceSolver` appends that geometry to each eye's feature vector, so every
observation (`Subject.observe`) carries what its frame needs, exact or interpolated exactly like the
features. Channels per eye, full-sensor px (OpenCV convention), after the `PUPIL_CHANNELS + 2 L` feature
channels of `solver` (L LEDs of the scene):

    pupil outline   N x (x, y)  the forward model's N refracted pupil boundary points, evenly spaced
                                around the stop (NaN unless all N could be traced: the fitted ellipse is
                                drawn instead)
    limbus          centre x, y, second moments m_xx, m_yy, m_xy (px^2; `solver.ellipse_to_moments`)
    upper lid       K x (x, y)  margin polyline from canthus to canthus, by increasing image x
    lower lid       K x (x, y)
    scale           px per mm at the limbus (eyelash length)

`outline_from_rows` turns rows of such channels back into an `EyeOutline` for `render.render_window`.
NaN channels (a blink: the subject reports nothing) give an outline that draws nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eyehil.emulator.device.solver import PUPIL_CHANNELS, FeatureSolver, ellipse_from_moments, ellipse_to_moments
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.features import Features
from eyehil.emulator.forward import simulate
from eyehil.emulator.render.geometry import Eyelids, EyeOutline, eye_outlines, pupil_polar
from eyehil.emulator.scene import HeadPose, Scene


@dataclass(frozen=True)
class ChannelLayout:
    """Where each quantity sits in one eye's channel vector (see the module docstring)."""

    n_leds: int
    n_points: int = 30
    lid_points: int = Eyelids().n_points

    @property
    def features(self) -> int:
        """Channels of the features proper (`eyehil.emulator.device.solver`)."""
        return PUPIL_CHANNELS + 2 * self.n_leds

    def _span(self, index: int) -> slice:
        sizes = (2 * self.n_points, 5, 2 * self.lid_points, 2 * self.lid_points, 1)
        start = self.features + sum(sizes[:index])
        return slice(start, start + sizes[index])

    @property
    def pupil_points(self) -> slice:
        return self._span(0)

    @property
    def limbus(self) -> slice:
        return self._span(1)

    @property
    def upper_lid(self) -> slice:
        return self._span(2)

    @property
    def lower_lid(self) -> slice:
        return self._span(3)

    @property
    def scale(self) -> slice:
        return self._span(4)

    @property
    def total(self) -> int:
        """Channels per eye, features and appearance."""
        return self.scale.stop


def feature_channels(f: Features) -> np.ndarray:
    """The feature channels (T, S, PUPIL_CHANNELS + 2 L) of forward-model features of one eye and head (1, S, 1, T):
    the same values as `FeatureSolver.solve` (tests/device/test_frames_e2e.py checks that they agree)."""
    ok = f.fixation_valid[0, :, 0] & f.pupil_valid[0, :, 0]
    pupil = np.concatenate([f.pupil_centre_px[0, :, 0],
                            ellipse_to_moments(f.pupil_axes_px[0, :, 0], f.pupil_angle_deg[0, :, 0])], -1)
    pupil = np.where(ok[..., None], pupil, np.nan)
    glint_ok = f.glint_valid[0, :, 0] & f.fixation_valid[0, :, 0][..., None]
    glints = np.where(glint_ok[..., None], f.glint_px[0, :, 0], np.nan).reshape(*ok.shape, -1)
    return np.concatenate([pupil, glints], axis=-1).transpose(1, 0, 2)


def appearance_channels(o: EyeOutline) -> np.ndarray:
    """The appearance channels (T, S, A) of outlines of one eye and head (1, S, 1, T)."""
    o = o[0, :, 0]  # (S, T)
    traced = np.all(np.isfinite(o.pupil_points_px), axis=(-2, -1))
    points = np.where(traced[..., None, None], o.pupil_points_px, np.nan)
    limbus = np.concatenate([o.limbus_centre_px, ellipse_to_moments(o.limbus_axes_px, o.limbus_angle_deg)], -1)
    flat = [points, limbus, o.upper_lid_px, o.lower_lid_px, o.px_per_mm[..., None]]
    out = np.concatenate([a.reshape(*o.shape, -1) for a in flat], axis=-1)
    return out.transpose(1, 0, 2)


class AppearanceSolver(FeatureSolver):
    """A `FeatureSolver` whose channels also carry the appearance of each eye (module docstring)."""

    def __init__(self, eye: EyeModel, scene: Scene, head: HeadPose | None = None, *, eyelids: Eyelids | None = None,
                 **kwargs) -> None:
        """As `FeatureSolver`; `eyelids`: the lid geometry drawn (default `render_geometry.Eyelids()`)."""
        super().__init__(eye, scene, head, **kwargs)
        self.eyelids = eyelids or Eyelids()
        self.layout = ChannelLayout(self.n_leds, self.n_points, self.eyelids.n_points)
        self.n_channels = self.layout.total

    def solve(self, xy: np.ndarray) -> np.ndarray:
        """Exact features and appearance (N, E, C) of gaze points (N, 2) screen mm: one forward-model call."""
        f = simulate(self.eye, self.scene, targets=self.world(xy), head_positions=(self.head,),
                     n_pupil_points=self.n_points)
        outline = eye_outlines(f, self.eye, self.scene, lids=self.eyelids)
        return np.concatenate([feature_channels(f), appearance_channels(outline)], axis=-1)


def outline_from_rows(rows: np.ndarray, layout: ChannelLayout, sensor_px: tuple[int, int], leds: int | None = None
                      ) -> EyeOutline:
    """An `EyeOutline` (n,) of channel rows (n, C) of `layout`, with the glints of the first `leds` LEDs (lit)."""
    rows = np.atleast_2d(np.asarray(rows, float))
    n, leds = len(rows), layout.n_leds if leds is None else leds
    centre, limbus = rows[:, 0:2], rows[:, layout.limbus]
    both_axes, both_angles = ellipse_from_moments(np.nan_to_num(np.stack([rows[:, 2:PUPIL_CHANNELS], limbus[:, 2:]],
                                                                        axis=1)))  # pupil, limbus (n, 2, ...)
    (axes, limbus_axes), (angle, limbus_angle) = both_axes.transpose(1, 0, 2), both_angles.T
    glints = rows[:, PUPIL_CHANNELS:layout.features].reshape(n, layout.n_leds, 2)[:, :leds]
    points = rows[:, layout.pupil_points].reshape(n, layout.n_points, 2)
    theta, r, dr = pupil_polar(points, np.isfinite(points).all(-1), centre, axes, angle)
    return EyeOutline(
        pupil_centre_px=centre, pupil_axes_px=axes, pupil_angle_deg=angle,
        pupil_valid=np.isfinite(rows[:, :PUPIL_CHANNELS]).all(-1), pupil_points_px=points, pupil_theta=theta,
        pupil_r=r, pupil_dr=dr, limbus_centre_px=limbus[:, :2], limbus_axes_px=limbus_axes,
        limbus_angle_deg=limbus_angle, glint_px=glints, glint_valid=np.isfinite(glints).all(-1),
        upper_lid_px=rows[:, layout.upper_lid].reshape(n, -1, 2),
        lower_lid_px=rows[:, layout.lower_lid].reshape(n, -1, 2),
        px_per_mm=rows[:, layout.scale][:, 0], sensor_px=tuple(int(v) for v in sensor_px))


def closed(row: np.ndarray, layout: ChannelLayout) -> np.ndarray:
    """Channels (C,) of the same eye with its upper lid lowered onto the lower one (a blink at 1)."""
    out = np.array(row, float)
    out[layout.upper_lid] = out[layout.lower_lid]
    return out
