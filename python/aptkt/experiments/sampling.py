"""Seeds and random object groups of the experiments, all derived from one root seed.

Every random choice of an experiment (which objects form a group, the order a run draws its
pool observations in, its exploration coin flips) comes from :func:`derive_seed` with the
root seed and a key naming the choice, so a figure repeats exactly from ``--seed`` alone and
two figures that name the same choice (fig7 and fig9 with 3 priors) make it identically.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["derive_seed", "draw_groups"]


def _part(key: int | str) -> int:
    if isinstance(key, (int, np.integer)):
        if key < 0:
            raise InvalidInputError(f"seed keys must be >= 0, got {key}")
        return int(key)
    return zlib.crc32(str(key).encode())


def derive_seed(root: int, *keys: int | str) -> int:
    """A 31-bit seed from the root seed and a key path, e.g. ``derive_seed(0, "trial", 3, g, t)``.

    Independent streams for different keys (numpy's ``SeedSequence`` spawn keys), stable across
    machines and Python versions (strings enter through CRC-32, not ``hash``).
    """
    if root < 0:
        raise InvalidInputError(f"the root seed must be >= 0, got {root}")
    seq = np.random.SeedSequence(entropy=int(root), spawn_key=tuple(_part(k) for k in keys))
    return int(seq.generate_state(1, np.uint32)[0] >> 1)


def draw_groups(objects: Sequence[str], size: int, count: int, seed: int) -> list[tuple[str, ...]]:
    """``count`` distinct groups of ``size`` objects, each drawn uniformly without replacement.

    Groups keep the order of ``objects`` (the library's order) and never repeat; when fewer than
    ``count`` distinct groups exist (e.g. 10 of 10 objects) every possible group is returned
    once. Deterministic for a given seed.
    """
    objects = list(objects)
    if not 1 <= size <= len(objects):
        raise InvalidInputError(f"cannot draw groups of {size} from {len(objects)} objects")
    if count < 1:
        raise InvalidInputError(f"count must be >= 1, got {count}")
    possible = math.comb(len(objects), size)
    count = min(count, possible)
    rng = np.random.default_rng(seed)
    groups: list[tuple[str, ...]] = []
    seen: set[tuple[str, ...]] = set()
    while len(groups) < count:
        pick = sorted(rng.choice(len(objects), size=size, replace=False).tolist())
        group = tuple(objects[i] for i in pick)
        if group not in seen:
            seen.add(group)
            groups.append(group)
    return groups
