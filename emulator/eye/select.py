"""Choose eyes by a short text spec (command line and configuration files).

- `published`: the 100 eyes of the published study (Fischer et al. 2023);
- `published:full`: the same eyes with the anatomy the study left out (`anatomy.full_anatomy`: astigmatism
  drawn conditionally on their parameters, pupil decentration, elliptical stop, corneal tilt; the seed's draws);
- `sample:N` (or just `N`): N eyes drawn from the Rozema 2011 population with the given seed;
  `sample:N:astigmatic` keeps their drawn corneal astigmatism (toric corneas);
- `normative:NAME`: one named normative eye (`navarro`, `atchison`, `et_simul`, `mean`, `gka`).
"""

from __future__ import annotations

import numpy as np

from eyehil.emulator.eye.model import EyeModel


def eyes_from_spec(spec: str, seed: int = 0) -> tuple[EyeModel, str]:
    """(eyes as a batch, a one-line description)."""
    kind, _, arg = spec.partition(":")
    if kind.isdigit() and not arg:
        kind, arg = "sample", kind
    if kind == "published" and arg in ("", "full"):
        from eyehil.emulator.eye.published import published_eyes

        if arg == "full":
            from eyehil.emulator.eye.anatomy import full_anatomy

            eyes = full_anatomy(published_eyes(), np.random.default_rng(seed))
            return eyes, f"the 100 eyes of Fischer et al. 2023 with full anatomy (seed {seed})"
        return published_eyes(), "the 100 eyes of Fischer et al. 2023"
    if kind == "sample":
        from eyehil.emulator.eye.population import sample

        count, _, option = arg.partition(":")
        if not count.isdigit() or int(count) <= 0 or option not in ("", "astigmatic"):
            raise ValueError(f"eyes spec {spec!r}: sample needs a positive count, e.g. sample:100 or "
                             "sample:100:astigmatic")
        draw = sample(int(count), np.random.default_rng(seed), astigmatism=bool(option))
        return draw.eyes, f"Rozema 2011 population{' (astigmatic)' if option else ''}, seed {seed}: {draw.summary()}"
    if kind == "normative" and arg:
        from eyehil.emulator.eye.normative import normative_eye

        return normative_eye(arg).as_batch(), f"normative eye {arg}"
    raise ValueError(f"eyes spec {spec!r}: use 'published', 'published:full', 'sample:N[:astigmatic]' or "
                     "'normative:NAME'")
