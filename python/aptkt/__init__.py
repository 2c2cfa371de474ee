"""aptkt: Active Prior Tactile Knowledge Transfer for a robot arm with a multi-modal skin."""

from importlib.metadata import PackageNotFoundError, version

try:
    # The installed distribution's version: maturin writes the Rust workspace's (Cargo.toml)
    # into the package metadata, so the version is written in one place.
    __version__ = version("aptkt")
except PackageNotFoundError:  # a source tree on the path, never installed
    from aptkt._core import __version__

__all__ = ["__version__"]
