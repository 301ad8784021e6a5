"""Anatomy: EyeModel, the Rozema 2011 population, normative eyes, media (indices).

- `model`: `EyeModel` (struct of arrays; mm, degrees, eye frame); `surfaces`: its optical surfaces;
- `biometry`: an EyeModel from biometry; `posterior`: posterior segment, fovea, rotation centres;
- `rozema`: the Rozema 2011 model as data; `population`: eyes drawn from it (`sample`);
- `published`: the 100 eyes of Fischer et al. 2023; `normative`: named normative eyes; `media`: indices;
- `astigmatism`: power vectors <-> toric radii; `anatomy`: `full_anatomy` (astigmatism, decentration, stop, tilt);
- `select`: eyes chosen by a short text spec (`published`, `published:full`, `sample:N[:astigmatic]`, `normative:NAME`).
"""

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.normative import normative_eye, normative_media
from eyehil.emulator.eye.population import PopulationDraw, sample
from eyehil.emulator.eye.published import published_eyes

__all__ = ["EyeModel", "Media", "PopulationDraw", "normative_eye", "normative_media", "published_eyes", "sample"]
