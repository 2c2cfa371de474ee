"""A bounded ring buffer of skin samples between a source's reader thread and its consumer."""

from __future__ import annotations

from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.skin.samples import FIELDS, SkinSamples

__all__ = ["SampleRing"]


class SampleRing:
    """Fixed-capacity FIFO of sample rows. When full, the oldest rows are dropped and counted
    in :attr:`overflows` (a consumer that falls behind loses old data, never blocks the link).
    Not thread-safe on its own: the owning source serialises access."""

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise InvalidInputError(f"ring capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self._cols: dict[str, Any] = {
            name: np.zeros((self.capacity, *tail), dtype) for name, (tail, dtype) in FIELDS.items()
        }
        self._head = 0  # index of the oldest row
        self._count = 0
        self.overflows = 0

    def __len__(self) -> int:
        return self._count

    def push(self, samples: SkinSamples) -> None:
        n = len(samples)
        if n == 0:
            return
        if n > self.capacity:
            self.overflows += n - self.capacity
            samples = samples.take(slice(n - self.capacity, None))
            n = self.capacity
        dropped = max(0, self._count + n - self.capacity)
        if dropped:
            self.overflows += dropped
            self._head = (self._head + dropped) % self.capacity
            self._count -= dropped
        start = (self._head + self._count) % self.capacity
        first = min(n, self.capacity - start)
        for name in FIELDS:
            src = getattr(samples, name)
            col = self._cols[name]
            col[start : start + first] = src[:first]
            col[: n - first] = src[first:]
        self._count += n

    def drain(self) -> SkinSamples:
        """All buffered rows, oldest first; the ring is empty afterwards."""
        idx = (self._head + np.arange(self._count)) % self.capacity
        out = SkinSamples(**{name: col[idx] for name, col in self._cols.items()})
        self._head = 0
        self._count = 0
        return out
