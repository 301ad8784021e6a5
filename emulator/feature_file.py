"""Features on disk, written chunk by chunk: memory stays bounded by one chunk of eyes whatever the number of eyes.

Two forms, chosen by the path:

- a folder (any path not ending in ``.npz``): one NumPy ``.npy`` file per array of `eyehil.emulator.features`
  (shaped E eyes x S sides x H head positions x T targets x ...), plus ``leds.npy``, ``targets.npy`` (when the
  fixations had targets) and ``meta.json`` (scene, media, sides, head position names, eyes). Any ``.npy`` opens
  alone with ``numpy.load(path, mmap_mode="r")``;
- ``FILE.npz``: the same arrays in one compressed NumPy archive (`numpy.load(FILE)`), as ``Features.save`` writes.

An existing target is replaced only if it is an earlier output (a features folder, an empty folder, or a file
for ``.npz``); anything else is refused before any work (`FileExistsError`).

`FeatureWriter` takes chunks of eyes in any order (`write(first_eye, features)`), writing each straight into its
rows of the ``.npy`` files with plain file I/O (no memory map, so nothing accumulates in the process's memory); a
run that fails leaves no output (the folder is built beside the target as ``NAME.partial`` and renamed at the
end; an ``.npz`` is packed from it, entry by entry). `load_features(path)` reads either form back.
"""

from __future__ import annotations

import ast
import json
import shutil
import zipfile
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from eyehil.emulator.features import ARRAYS, Features

#: bytes copied at a time when packing the .npz
COPY_BYTES = 1 << 20


class FeatureWriter:
    """Write the features of `n_eyes` eyes chunk by chunk to `path` (a folder, or FILE.npz); use as a context
    manager: on leaving it normally the output appears complete, on an error nothing is left behind."""

    def __init__(self, path: str | Path, n_eyes: int) -> None:
        if n_eyes < 1:
            raise ValueError("n_eyes must be >= 1")
        self.path = Path(path)
        self.packed = self.path.suffix == ".npz"
        self.n_eyes = n_eyes
        self.stage = self.path.with_name(self.path.name + ".partial")
        _check_replaceable(self.path, self.packed)
        self._files: dict[str, tuple[BinaryIO, int, int]] = {}  # name -> (file, header bytes, bytes per eye)
        self._meta: dict[str, Any] | None = None
        self._rows = np.zeros(n_eyes, dtype=bool)

    def __enter__(self) -> FeatureWriter:
        if self.stage.exists():
            shutil.rmtree(self.stage)
        self.stage.mkdir(parents=True)
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        for fh, _, _ in self._files.values():
            fh.close()
        if kind is not None:
            shutil.rmtree(self.stage, ignore_errors=True)
            return
        self._finish()

    def write(self, first_eye: int, features: Features) -> None:
        """The rows first_eye .. first_eye + E - 1 (E: the chunk's eyes)."""
        n = features.shape[0]
        if first_eye < 0 or first_eye + n > self.n_eyes:
            raise ValueError(f"eyes {first_eye}..{first_eye + n - 1} are outside 0..{self.n_eyes - 1}")
        if self._meta is None:
            self._start(features)
        for name in ARRAYS:
            value = np.ascontiguousarray(features.arrays[name])
            fh, header, per_eye = self._files[name]
            if value.nbytes != n * per_eye:
                raise ValueError(f"{name}: a chunk shaped {value.shape} does not match the file's rows")
            fh.seek(header + first_eye * per_eye)
            fh.write(value.tobytes())
        self._rows[first_eye:first_eye + n] = True

    def _start(self, features: Features) -> None:
        self._meta = {"format": "eyehil.features/1", "scene": features.scene, "media": features.media,
                      "sides": list(features.sides), "eyes": self.n_eyes,
                      "head_positions": [getattr(h, "name", str(h)) for h in features.head_positions]}
        np.save(self.stage / "leds.npy", features.leds)
        if features.targets is not None:
            np.save(self.stage / "targets.npy", features.targets)
        for name in ARRAYS:
            value = features.arrays[name]
            shape = (self.n_eyes, *value.shape[1:])
            fh = open(self.stage / f"{name}.npy", "wb")  # noqa: SIM115 (closed in __exit__)
            np.lib.format.write_array_header_1_0(
                fh, {"descr": np.lib.format.dtype_to_descr(value.dtype), "fortran_order": False, "shape": shape})
            per_eye = value.dtype.itemsize * int(np.prod(shape[1:], dtype=np.int64))
            fh.truncate(fh.tell() + self.n_eyes * per_eye)
            self._files[name] = (fh, fh.tell(), per_eye)

    def _finish(self) -> None:
        if self._meta is None or not self._rows.all():
            missing = np.flatnonzero(~self._rows)
            shutil.rmtree(self.stage, ignore_errors=True)
            raise RuntimeError(f"features of {len(missing)} eye(s) were never written (first: eye {missing[0]})")
        (self.stage / "meta.json").write_text(json.dumps(self._meta, indent=1))
        if self.packed:
            _pack(self.stage, self.path)
            shutil.rmtree(self.stage)
            return
        _check_replaceable(self.path, self.packed)  # again: something may have appeared during the run
        if self.path.exists():
            shutil.rmtree(self.path)
        self.stage.rename(self.path)


def _check_replaceable(path: Path, packed: bool) -> None:
    """Refuse (before any work) a target that is not ours to replace: anything but an earlier features folder
    (its meta.json says eyehil.features) or, for FILE.npz, a file."""
    if not path.exists():
        return
    if packed and path.is_file():
        return
    if not packed and path.is_dir():
        meta = path / "meta.json"
        try:
            ours = json.loads(meta.read_text()).get("format", "").startswith("eyehil.features/")
        except (OSError, ValueError, AttributeError):
            ours = False
        if ours or not any(path.iterdir()):
            return
    raise FileExistsError(f"{path} exists and is not an earlier eyehil features output: choose another --out")


def _pack(folder: Path, target: Path) -> None:
    """The folder's .npy files (and meta, as `Features.save` writes it) into one compressed .npz, copied in
    blocks; written beside the target and renamed, so a reader never sees half an archive."""
    meta = json.loads((folder / "meta.json").read_text())
    partial = target.with_name(target.name + ".part")
    with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
        with archive.open("meta.npy", "w") as entry:
            np.lib.format.write_array(entry, np.array(repr({k: meta[k] for k in (
                "scene", "sides", "media", "head_positions")})))
        for npy in sorted(folder.glob("*.npy")):
            with open(npy, "rb") as src, archive.open(npy.name, "w", force_zip64=True) as entry:
                shutil.copyfileobj(src, entry, COPY_BYTES)
    partial.replace(target)


def load_features(path: str | Path, *, mmap: bool = True) -> Features:
    """Features from a folder `FeatureWriter` wrote (memory-mapped read-only unless `mmap` is False) or from an
    .npz (`FeatureWriter` or `Features.save`). Head positions come back as their names."""
    path = Path(path)
    if path.is_dir():
        meta = json.loads((path / "meta.json").read_text())
        mode = "r" if mmap else None
        arrays = {name: np.load(path / f"{name}.npy", mmap_mode=mode) for name in ARRAYS}
        leds = np.load(path / "leds.npy")
        targets = np.load(path / "targets.npy") if (path / "targets.npy").exists() else None
    else:
        with np.load(path) as archive:
            meta = ast.literal_eval(str(archive["meta"]))
            arrays = {name: archive[name] for name in ARRAYS}
            leds = archive["leds"]
            targets = archive["targets"] if "targets" in archive.files else None
    return Features(scene=meta["scene"], sides=tuple(meta["sides"]), head_positions=tuple(meta["head_positions"]),
                    leds=leds, targets=targets, media=meta["media"], arrays=arrays)


__all__ = ["FeatureWriter", "load_features"]
