"""`eyehil simulate`: run the forward model on a scene and print a readable summary.

With no arguments: the published study's 100 eyes in the Guestrin 2006 scene. The eyes are split into chunks
that run on a local process pool (`--workers`, default one per core) or a Dask cluster (`--scheduler`); each
chunk's features are written away as it arrives (`--out FILE.npz` or `--out FOLDER` of .npy files, see
`eyehil.emulator.feature_file`) and folded into the summary (`Digest`), so memory stays bounded by the chunks in
flight whatever the number of eyes.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from contextlib import closing, nullcontext
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from eyehil.emulator.scene.presets_index import preset_names

if TYPE_CHECKING:
    import numpy as np

    from eyehil.emulator.features import Features

# The parser is built without numpy (`eyehil simulate --help` stays fast); `run` imports the forward model.

#: eyes per chunk at most (about 0.2 MB of features per eye and fixation set at 30 pupil points)
MAX_CHUNK_EYES = 200


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="ray-trace eyes fixating the targets of a scene; print a summary",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="guestrin2006", help=f"preset ({', '.join(preset_names())}) or TOML path")
    p.add_argument("--eyes", default="published", help="published | sample:N | normative:NAME (default published)")
    p.add_argument("--seed", type=int, default=0, help="random seed for sampled eyes")
    p.add_argument("--media", choices=["scene", "cauchy", "study-code"], default="scene",
                   help="refractive indices (default: as the scene says)")
    p.add_argument("--points", type=int, default=30, help="pupil boundary points per fixation (default 30)")
    p.add_argument("--out", help="write the features to FILE.npz (compressed) or to a folder of .npy files")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address (optional extra 'dask')")
    p.add_argument("--chunk-eyes", type=int, default=None,
                   help=f"eyes per chunk (default: about four chunks per worker, at most {MAX_CHUNK_EYES})")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def chunk_size(n_eyes: int, workers: int) -> int:
    """About four chunks per worker (progress, balance), at most MAX_CHUNK_EYES eyes (memory)."""
    return max(1, min(MAX_CHUNK_EYES, math.ceil(n_eyes / (4 * max(1, workers)))))


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from eyehil.emulator.eye.media import Media
    from eyehil.emulator.eye.select import eyes_from_spec
    from eyehil.emulator.feature_file import FeatureWriter
    from eyehil.emulator.forward import simulate
    from eyehil.emulator.scene import load_scene
    from eyehil.parallel import default_workers, iter_chunks

    for name in ("points", "workers", "chunk_eyes"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1")
    scene = load_scene(args.scene)
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    media = None if args.media == "scene" else Media.named(args.media, scene.wavelength_nm)
    workers = args.workers or default_workers()
    size = args.chunk_eyes or chunk_size(len(eyes), workers)
    firsts = list(range(0, len(eyes), size))
    chunks = [eyes[a:a + size] for a in firsts]
    digest: Digest | None = None
    start = time.perf_counter()
    writer = FeatureWriter(args.out, len(eyes)) if args.out else nullcontext()
    with tqdm(total=len(eyes), unit="eye", disable=args.quiet, desc="ray tracing") as bar, writer as out:
        done = iter_chunks(simulate, chunks, sizes=[len(c) for c in chunks], workers=workers,
                           scheduler=args.scheduler, progress=bar.update, scene=scene, media=media,
                           n_pupil_points=args.points)
        with closing(done):  # an error here stops the workers at once
            for i, features in done:
                if out is not None:
                    out.write(firsts[i], features)
                part = Digest.of(features)
                digest = part if digest is None else digest + part
    elapsed = time.perf_counter() - start
    assert digest is not None
    print(summary(digest, about, elapsed))
    for line in warnings(digest):
        print(f"eyehil simulate: warning: {line}", file=sys.stderr)
    if args.out:
        print(f"features written to {args.out} ({'compressed .npz' if out.packed else 'a folder of .npy files'})")
    return 0


def _range(values: np.ndarray) -> tuple[float, float]:
    """(min, max) of the finite values; NaN, NaN when there are none."""
    import numpy as np

    finite = values[np.isfinite(values)]
    return (float(finite.min()), float(finite.max())) if finite.size else (math.nan, math.nan)


def _merge_range(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    lo = [v for v in (a[0], b[0]) if not math.isnan(v)]
    hi = [v for v in (a[1], b[1]) if not math.isnan(v)]
    return (min(lo) if lo else math.nan, max(hi) if hi else math.nan)


#: stages a fixation can fail, and the validity array of each (a fixation fails if any of its parts does)
STAGES = (("the fixation solve failed", "fixation_valid"), ("no pupil image", "pupil_valid"),
          ("glints invalid", "glint_valid"))


@dataclass
class Digest:
    """What the summary and the warnings need of a forward run, computed per chunk of eyes and merged (`+`), so
    that the features themselves need not stay in memory. Ranges in px, mm or deg as in `Features`."""

    scene: str
    media: str
    sides: tuple[str, ...]
    head_positions: tuple[Any, ...]
    n_eyes: int
    n_targets: int
    n_leds: int
    counts: dict[str, int]
    ranges: dict[str, tuple[float, float]]
    cells: dict[str, Any] = field(default_factory=dict)  # name -> (S, H) int array of fixations

    @classmethod
    def of(cls, f: Features) -> Digest:
        import numpy as np

        ok = f.valid
        pg = np.linalg.norm(f.pupil_glint_px[..., 0, :], axis=-1)
        ranges = {
            "fixation_residual_mm": _range(f.fixation_residual_mm), "glint_residual_mm": _range(f.glint_residual_mm),
            "pupil_residual_mm": _range(f.pupil_residual_mm), "azimuth_deg": _range(f.azimuth_deg),
            "elevation_deg": _range(f.elevation_deg), "pupil_major_px": _range(f.pupil_axes_px[..., 0]),
            "pupil_glint_px": _range(pg[ok]),
            "glint_separation_px": (_range(np.linalg.norm(f.glint_px[..., 0, :] - f.glint_px[..., 1, :], axis=-1))
                                    if f.glint_px.shape[-2] >= 2 else (math.nan, math.nan)),
        }
        e, s, h, t = f.shape
        cells = {"n": np.full((s, h), e * t), "valid": ok.sum(axis=(0, 3)),
                 "visible": (ok & f.in_image).sum(axis=(0, 3))}
        for what, name in STAGES:
            failed = ~getattr(f, name).reshape(e, s, h, t, -1).all(axis=-1)
            cells[what] = failed.sum(axis=(0, 3))
        return cls(scene=f.scene, media=f.media, sides=tuple(f.sides), head_positions=tuple(f.head_positions),
                   n_eyes=e, n_targets=t, n_leds=f.glint_px.shape[-2], counts=f.counts(), ranges=ranges,
                   cells=cells)

    def __add__(self, other: Digest) -> Digest:
        if (self.sides, len(self.head_positions), self.n_targets) != (other.sides, len(other.head_positions),
                                                                      other.n_targets):
            raise ValueError("digests of different set-ups cannot be merged")
        return Digest(scene=self.scene, media=self.media, sides=self.sides, head_positions=self.head_positions,
                      n_eyes=self.n_eyes + other.n_eyes, n_targets=self.n_targets, n_leds=self.n_leds,
                      counts={k: v + other.counts[k] for k, v in self.counts.items()},
                      ranges={k: _merge_range(v, other.ranges[k]) for k, v in self.ranges.items()},
                      cells={k: v + other.cells[k] for k, v in self.cells.items()})


def summary(d: Digest, about: str, seconds: float) -> str:
    """A readable report of a forward run."""
    n = d.counts["fixations"]
    r = d.ranges
    counts = d.counts
    glint_span = ""
    if d.n_leds >= 2:
        glint_span = (f"\n  glint separation    {r['glint_separation_px'][0]:.1f} .. {r['glint_separation_px'][1]:.1f} "
                      "px")
    lines = [
        f"scene {d.scene} ({d.media}); eyes: {about}",
        f"  fixations           {n} = {d.n_eyes} eyes x {len(d.sides)} side(s) x {len(d.head_positions)} head "
        f"position(s) x {d.n_targets} targets, in {seconds:.2f} s ({n / max(seconds, 1e-9):,.0f} fixations/s)",
        f"  valid               {counts['valid']} (fixation failed {counts['fixation_failed']}, pupil failed "
        f"{counts['pupil_failed']}, glints invalid {counts['glints_invalid']}, pupil points blocked "
        f"{counts['pupil_points_blocked']})",
        f"  off the sensor      {counts['off_sensor']} valid fixations extrapolated beyond the image",
        f"  max residuals       fixation {r['fixation_residual_mm'][1]:.1e} mm, glint "
        f"{r['glint_residual_mm'][1]:.1e} mm, pupil {r['pupil_residual_mm'][1]:.1e} mm",
        f"  gaze angles         azimuth {r['azimuth_deg'][0]:+.1f} .. {r['azimuth_deg'][1]:+.1f} deg, "
        f"elevation {r['elevation_deg'][0]:+.1f} .. {r['elevation_deg'][1]:+.1f} deg",
        f"  pupil diameter      {r['pupil_major_px'][0]:.1f} .. {r['pupil_major_px'][1]:.1f} px (major axis)",
        f"  pupil-glint vector  {r['pupil_glint_px'][0]:.1f} .. {r['pupil_glint_px'][1]:.1f} px (LED 1){glint_span}",
    ]
    return "\n".join(lines)


def warnings(d: Digest) -> list[str]:
    """Set-ups that make the physics impossible, one line each: a side and head position with no valid fixation
    (and why: the fixation solve, the pupil or the glints failed), or whose valid fixations all lie off the
    camera's image (extrapolated beyond the sensor)."""
    import numpy as np

    out = []
    for s, side in enumerate(d.sides):
        for h, head in enumerate(d.head_positions):
            name = getattr(head, "name", str(head))
            t = getattr(head, "translation", None)
            where = f"{side} eye, head position {name!r}" + (
                "" if t is None else f" (at {', '.join(f'{v:g}' for v in np.ravel(t))} mm)")
            n, valid = int(d.cells["n"][s, h]), int(d.cells["valid"][s, h])
            if not valid:
                why = ", ".join(f"{what} for {int(d.cells[what][s, h])}" for what, _ in STAGES
                                if d.cells[what][s, h])
                out.append(f"{where}: no valid fixation of {n} ({why or 'no reason recorded'})")
            elif not d.cells["visible"][s, h]:
                out.append(f"{where}: all {valid} valid fixations lie off the camera's image")
    return out
