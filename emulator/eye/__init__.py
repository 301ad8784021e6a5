"""Anatomy: EyeModel, the Rozema 2011 population, normative eyes, media (indices)."""

from eyehil.emulator.eye.media import Media
from eyehil.emulator.eye.model import EyeModel
from eyehil.emulator.eye.normative import normative_eye, normative_media
from eyehil.emulator.eye.population import PopulationDraw, sample
from eyehil.emulator.eye.published import published_eyes

__all__ = ["EyeModel", "Media", "PopulationDraw", "normative_eye", "normative_media", "published_eyes", "sample"]
