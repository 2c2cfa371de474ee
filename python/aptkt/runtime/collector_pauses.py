"""Keep Python's cyclic garbage collector from pausing a trial on a live robot.

A collection stops the whole interpreter while it scans the heap: every thread of aptkt's
process waits, the skin's reader and the supervision of the arm among them. With numpy, SciPy,
scikit-learn, h5py and ur_rtde loaded, a full collection scans some 160,000 objects and takes
0.1–0.4 s (measured; longer on a busy machine). That is longer than a patch's silence timeout
(0.1 s by default): one collection that falls inside a recording leaves every cell without a
packet for that long, and the trial fails as a silent skin (seen in a loaded test run). Hence:

- :func:`heap_frozen` for a session: the objects that exist once the robot is connected (the
  imported modules, mostly) are moved out of the collector's reach (``gc.freeze``), so that a
  later collection scans only what the session made since;
- :func:`no_collector_pauses` for a trial: no automatic collection from the approach to the end
  of the trial, and one collection after it, with the arm lifted off and no recording running.

Reference counting frees all but cyclic garbage meanwhile; what a trial leaves in cycles is
collected as it ends.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["heap_frozen", "no_collector_pauses"]


@contextmanager
def heap_frozen() -> Iterator[None]:
    """Freeze the heap as it is now for the time of the block (unless the program froze it
    itself: then its own freeze stands, and is left to it)."""
    if gc.get_freeze_count():
        yield
        return
    gc.collect()  # (what is garbage now is collected, not kept for ever)
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@contextmanager
def no_collector_pauses() -> Iterator[None]:
    """No automatic collection during the block; one as it ends (if the collector was on)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
            gc.collect()
