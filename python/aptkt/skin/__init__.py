"""The multi-modal skin: protocol parser, skin sources, recordings."""

from aptkt.skin.base import SkinSource
from aptkt.skin.samples import Recording, SkinSamples

__all__ = ["SkinSource", "SkinSamples", "Recording"]
