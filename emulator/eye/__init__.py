"""Anatomy: EyeModel, the Rozema 2011 population, normative eyes, media (indices)."""

from emulator.eye.media import Media
from emulator.eye.model import EyeModel
from emulator.eye.normative import normative_eye, normative_media
from emulator.eye.population import PopulationDraw, sample
from emulator.eye.published import published_eyes

__all__ = ["EyeModel", "Media", "PopulationDraw", "normative_eye", "normative_media", "published_eyes", "sample"]
