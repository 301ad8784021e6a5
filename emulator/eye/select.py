"""Choose eyes by a short text spec (command line and configuration files).

- `published`: the 100 eyes of the published study (Fischer et al. 2023);
- `sample:N` (or just `N`): N eyes drawn from the Rozema 2011 population with the given seed;
- `normative:NAME`: one named normative eye (`navarro`, `atchison`, `et_simul`, `mean`).
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.model import EyeModel


def eyes_from_spec(spec: str, seed: int = 0) -> tuple[EyeModel, str]:
    """(eyes as a batch, a one-line description)."""
    kind, _, arg = spec.partition(":")
    if kind.isdigit() and not arg:
        kind, arg = "sample", kind
    if kind == "published" and not arg:
        from eyehil.emulator.eye.published import published_eyes

        return published_eyes(), "the 100 eyes of Fischer et al. 2023"
    if kind == "sample":
        from eyehil.emulator.eye.population import sample

        if not arg.isdigit() or int(arg) <= 0:
            raise ValueError(f"eyes spec {spec!r}: sample needs a positive count, e.g. sample:100")
        draw = sample(int(arg), np.random.default_rng(seed))
        return draw.eyes, f"Rozema 2011 population, seed {seed}: {draw.summary()}"
    if kind == "normative" and arg:
        from eyehil.emulator.eye.normative import normative_eye

        return normative_eye(arg).as_batch(), f"normative eye {arg}"
    raise ValueError(f"eyes spec {spec!r}: use 'published', 'sample:N' or 'normative:NAME'")
