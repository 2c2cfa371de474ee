"""How a stream of objects is cut into batches for the lifelong benchmark: plain integers, no
numerical library (the command line reads :data:`LARGEST_BATCH` to build its help)."""

from __future__ import annotations

__all__ = ["LARGEST_BATCH", "schedule"]

#: A stream's batches grow with the library (each as large as the library) up to this many
#: objects.
LARGEST_BATCH = 50


def schedule(total: int, first: int, largest: int = LARGEST_BATCH) -> list[int]:
    """The sizes of the batches that take a library of ``first`` objects to ``total``: each as
    large as the library (at least ``first``, at most ``largest``); a last batch smaller than
    ``first`` is left out."""
    sizes, held = [], first
    while total - held >= first:
        size = min(max(held, first), largest, total - held)
        sizes.append(size)
        held += size
    return sizes
