"""Anatomy: EyeModel, the Rozema 2011 population, normative eyes, media (indices)."""

from emulator.eye.media import Media
from emulator.eye.model import EyeModel

__all__ = ["EyeModel", "Media"]
