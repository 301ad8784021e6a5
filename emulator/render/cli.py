"""`eyehil render`: write example synthetic infrared frames (PNG) and their ground truth (JSON).

With no options but `-o DIR`: four published eyes of Fischer et al. 2023 in the Guestrin 2006 scene, at
the central head position, fixating targets spread over the screen, as 320x240 regions of interest
around the eye. `--full` writes whole sensor frames instead (both eyes in binocular scenes). Ground
truth (full-sensor px, OpenCV convention) goes to DIR/truth.json: per frame the region's top-left pixel,
the pupil ellipse (centre, full axes, angle deg) and the glint centres per LED.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from eyehil.emulator.scene.presets_index import preset_names

if TYPE_CHECKING:
    import numpy as np

# The parser is built without numpy or OpenCV (`eyehil render --help` stays fast); `run` imports the renderer.


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="write example synthetic IR frames (PNG) with their ground truth",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--out", required=True, help="directory to write the frames into (created)")
    p.add_argument("--scene", default="guestrin2006", help=f"preset ({', '.join(preset_names())}) or TOML path")
    p.add_argument("--eyes", default="published", help="published | sample:N | normative:NAME (default published)")
    p.add_argument("--count", type=int, default=4, help="frames to write (default 4)")
    p.add_argument("--seed", type=int, default=0, help="random seed for sampled eyes and sensor noise")
    p.add_argument("--roi", default="320x240", help="region of interest WxH px (default 320x240)")
    p.add_argument("--full", action="store_true", help="whole sensor frames instead of regions of interest")
    p.add_argument("--blink", type=float, default=0.0, help="lid closure 0 (open) .. 1 (closed)")
    p.add_argument("--lashes", type=int, default=0, help="eyelashes per eye (default none)")
    p.add_argument("--gain-db", type=float, default=0.0, help="sensor gain (dB; noise grows with it)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from eyehil.emulator.eye.select import eyes_from_spec
    from eyehil.emulator.forward import simulate
    from eyehil.emulator.render.renderer import Appearance, RenderSettings, Sensor, render_features
    from eyehil.emulator.scene import load_scene

    if args.count <= 0:
        raise ValueError("--count must be positive")
    roi = None if args.full else _size(args.roi)
    scene = load_scene(args.scene)
    eyes, about = eyes_from_spec(args.eyes, args.seed)
    eyes = eyes[: min(args.count, len(eyes))]
    features = simulate(eyes, scene)
    n_targets = features.shape[3]
    picks = [(i % len(eyes), 0, 0, (i * max(n_targets // args.count, 1) + n_targets // 2) % n_targets)
             for i in range(args.count)]
    settings = RenderSettings(Appearance(lashes=args.lashes), Sensor(gain_db=args.gain_db))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    records = []
    frames = render_features(features, eyes, scene, np.random.default_rng(args.seed), index=picks, roi=roi,
                             blink=args.blink, settings=settings)
    stem = safe_stem(scene.name)
    for key, frame in frames:
        path = out / f"{stem}_{'_'.join(str(k) for k in key)}.png"
        if not cv2.imwrite(str(path), frame.image):
            raise ValueError(f"could not write {path}")
        records.append(_record(path.name, key, frame))
        print(f"wrote {path} ({frame.image.shape[1]}x{frame.image.shape[0]} px at {frame.roi_xy})")
    truth = out / "truth.json"
    truth.write_text(json.dumps({"scene": scene.name, "eyes": about, "frames": records}, indent=1), encoding="utf-8")
    print(f"wrote {truth} (ground truth of {len(records)} frames, full-sensor px)")
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise ValueError(f"--roi must look like 320x240, not {text!r}") from exc
    if w <= 0 or h <= 0:
        raise ValueError("--roi sizes must be positive")
    return w, h


def safe_stem(name: str) -> str:
    """`name` (a scene's, from a file anyone may write) as a file-name stem: letters, digits, ``-``, ``_``, ``.``
    only, no leading dot; so ``../ESCAPED`` or ``/etc/x`` cannot place a file outside the output folder."""
    stem = "".join(c if c.isascii() and (c.isalnum() or c in "-_.") else "_" for c in name).lstrip(".")
    return stem[:100] or "scene"


def _record(name: str, key: tuple[int, ...], frame) -> dict:
    """JSON-ready ground truth of one frame (NaN as null)."""
    import numpy as np

    t = frame.truth

    def clean(a: np.ndarray) -> list:
        return np.where(np.isfinite(a), np.round(a, 4), None).tolist()

    return {"file": name, "index": list(key), "roi_xy": list(frame.roi_xy), "pupil_centre_px": clean(t.pupil_centre_px),
            "pupil_axes_px": clean(t.pupil_axes_px), "pupil_angle_deg": clean(t.pupil_angle_deg),
            "pupil_visible": clean(t.pupil_visible), "glint_px": clean(t.glint_px),
            "glint_visible": t.glint_visible.tolist()}
