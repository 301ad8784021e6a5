"""`eyehil simulate`: run the forward model on a scene and print a readable summary.

With no arguments: the published study's 100 eyes in the Guestrin 2006 scene. `--out FILE.npz`
writes every feature array (see `eyehil.emulator.features`).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING

from eyehil.emulator.scene.presets_index import preset_names

if TYPE_CHECKING:
    from eyehil.emulator.features import Features

# The parser is built without numpy (`eyehil simulate --help` stays fast); `run` imports the forward model.


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="ray-trace eyes fixating the targets of a scene; print a summary",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="guestrin2006", help=f"preset ({', '.join(preset_names())}) or TOML path")
    p.add_argument("--eyes", default="published", help="published | sample:N | normative:NAME (default published)")
    p.add_argument("--seed", type=int, default=0, help="random seed for sampled eyes")
    p.add_argument("--media", choices=["scene", "cauchy", "study-code"], default="scene",
                   help="refractive indices (default: as the scene says)")
    p.add_argument("--points", type=int, default=30, help="pupil boundary points per fixation (default 30)")
    p.add_argument("--out", help="write the features to this .npz file")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from eyehil.emulator.eye.media import Media
    from eyehil.emulator.eye.select import eyes_from_spec
    from eyehil.emulator.forward import simulate
    from eyehil.emulator.scene import load_scene

    scene = load_scene(args.scene)
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    media = None if args.media == "scene" else Media.named(args.media, scene.wavelength_nm)
    start = time.perf_counter()
    with tqdm(total=len(eyes), unit="eye", disable=args.quiet, desc="ray tracing") as bar:
        features = simulate(eyes, scene, media=media, n_pupil_points=args.points, progress=bar.update)
    elapsed = time.perf_counter() - start
    print(summary(features, about, elapsed))
    for line in warnings(features):
        print(f"eyehil simulate: warning: {line}", file=sys.stderr)
    if args.out:
        print(f"features written to {features.save(args.out)}")
    return 0


def summary(f: Features, about: str, seconds: float) -> str:
    """A readable report of a forward run."""
    import numpy as np

    n = int(np.prod(f.shape))
    counts = f.counts()
    ok = f.valid
    glint_span = ""
    if f.glint_px.shape[-2] >= 2:
        sep = np.linalg.norm(f.glint_px[..., 0, :] - f.glint_px[..., 1, :], axis=-1)
        glint_span = f"\n  glint separation    {np.nanmin(sep):.1f} .. {np.nanmax(sep):.1f} px"
    pg = np.linalg.norm(f.pupil_glint_px[..., 0, :], axis=-1)
    lines = [
        f"scene {f.scene} ({f.media}); eyes: {about}",
        f"  fixations           {n} = {f.shape[0]} eyes x {len(f.sides)} side(s) x {len(f.head_positions)} head "
        f"position(s) x {f.shape[3]} targets, in {seconds:.2f} s ({n / max(seconds, 1e-9):,.0f} fixations/s)",
        f"  valid               {counts['valid']} (fixation failed {counts['fixation_failed']}, pupil failed "
        f"{counts['pupil_failed']}, glints invalid {counts['glints_invalid']}, pupil points blocked "
        f"{counts['pupil_points_blocked']})",
        f"  off the sensor      {counts['off_sensor']} valid fixations extrapolated beyond the image",
        f"  max residuals       fixation {np.nanmax(f.fixation_residual_mm):.1e} mm, glint "
        f"{np.nanmax(f.glint_residual_mm):.1e} mm, pupil {np.nanmax(f.pupil_residual_mm):.1e} mm",
        f"  gaze angles         azimuth {np.nanmin(f.azimuth_deg):+.1f} .. {np.nanmax(f.azimuth_deg):+.1f} deg, "
        f"elevation {np.nanmin(f.elevation_deg):+.1f} .. {np.nanmax(f.elevation_deg):+.1f} deg",
        f"  pupil diameter      {np.nanmin(f.pupil_axes_px[..., 0]):.1f} .. {np.nanmax(f.pupil_axes_px[..., 0]):.1f} px"
        f" (major axis)",
        f"  pupil-glint vector  {np.nanmin(pg[ok]) if ok.any() else np.nan:.1f} .. "
        f"{np.nanmax(pg[ok]) if ok.any() else np.nan:.1f} px (LED 1){glint_span}",
    ]
    return "\n".join(lines)


def warnings(f: Features) -> list[str]:
    """Set-ups that make the physics impossible, one line each: a side and head position with no valid fixation
    (and why: the fixation solve, the pupil or the glints failed), or whose valid fixations all lie off the
    camera's image (extrapolated beyond the sensor)."""
    import numpy as np

    out = []
    for s, side in enumerate(f.sides):
        for h, head in enumerate(f.head_positions):
            cell = (slice(None), s, h)
            name = getattr(head, "name", str(head))
            t = getattr(head, "translation", None)
            where = f"{side} eye, head position {name!r}" + (
                "" if t is None else f" (at {', '.join(f'{v:g}' for v in np.ravel(t))} mm)")
            n = int(np.prod(f.valid[cell].shape))
            valid = f.valid[cell]
            if not valid.any():
                shape = valid.shape  # a fixation fails a stage if any of its parts (LEDs) does
                reasons = {what: ~ok[cell].reshape(*shape, -1).all(axis=-1) for what, ok in (
                    ("the fixation solve failed", f.fixation_valid), ("no pupil image", f.pupil_valid),
                    ("glints invalid", f.glint_valid))}
                why = ", ".join(f"{k} for {int(np.count_nonzero(v))}" for k, v in reasons.items() if v.any())
                out.append(f"{where}: no valid fixation of {n} ({why or 'no reason recorded'})")
            elif not (valid & f.in_image[cell]).any():
                out.append(f"{where}: all {int(np.count_nonzero(valid))} valid fixations lie off the camera's image")
    return out
