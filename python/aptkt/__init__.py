"""aptkt: Active Prior Tactile Knowledge Transfer for a robot arm with a multi-modal skin."""

from __future__ import annotations

__all__ = ["__version__"]


def __getattr__(name: str) -> str:
    # Looked up on first use: importlib.metadata costs a tenth of a second of imports, and the
    # console script sets its signal handlers only once this package has been imported
    # (aptkt._entry).
    if name != "__version__":
        raise AttributeError(f"module 'aptkt' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        # The installed distribution's version: maturin writes the Rust workspace's
        # (Cargo.toml) into the package metadata, so the version is written in one place.
        found = version("aptkt")
    except PackageNotFoundError:  # a source tree on the path, never installed
        from aptkt._core import __version__ as found
    globals()["__version__"] = found
    return found
