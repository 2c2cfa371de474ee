"""aptkt: Active Prior Tactile Knowledge Transfer for a robot arm with a multi-modal skin."""

from aptkt._core import __version__

__all__ = ["__version__"]
