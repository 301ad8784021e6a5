"""Anatomy: EyeModel, the Rozema 2011 population, normative eyes, media (indices).

Modules: model (EyeModel), biometry (eyes from biometry), posterior (fovea angle, rotation centres, retina),
surfaces (the optical surfaces of an eye), media (refractive indices), rozema (the Rozema 2011 normal),
population (sampling it), published (the 100 eyes of Fischer et al. 2023), normative (named eyes),
astigmatism (power vectors <-> toric radii), anatomy (full_anatomy: astigmatism, decentration, stop, tilt),
select (choosing eyes).
"""

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.normative import normative_eye, normative_media
from eyehil.emulator.eye.population import PopulationDraw, sample
from eyehil.emulator.eye.published import published_eyes

__all__ = ["EyeModel", "Media", "PopulationDraw", "normative_eye", "normative_media", "published_eyes", "sample"]
