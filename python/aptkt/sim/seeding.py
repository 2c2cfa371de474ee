"""Deterministic randomness for the simulated world.

Two kinds of randomness are needed:

* **Per-trial draws** (where the object lies, how much its material varies, the room
  temperature, ...): a :class:`numpy.random.SeedSequence` keyed by ``(world seed, object,
  action, trial)``. Keys are hashed with BLAKE2b, never with Python's ``hash()`` (salted per
  process), so a trial's conditions do not depend on the order in which trials are run, on
  the process that runs them, or on which other trials exist.
* **Per-sample noise** (sensor noise, packet jitter, stick-slip thresholds): counter-based
  streams. Sample ``k`` of cell ``c`` always gets the same random numbers, however the
  simulation is chunked (one big open-loop segment or many closed-loop control ticks). This is
  what makes a closed-loop slide bit-for-bit reproducible.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Sequence

import numpy as np

from aptkt.errors import InvalidInputError, InvalidTypeError

__all__ = [
    "stable_words",
    "seed_sequence",
    "trial_seed_sequence",
    "CounterStream",
    "spawn_generators",
]

_TWO53 = float(2**53)


def stable_words(*parts: object) -> list[int]:
    """Four 32-bit words derived from ``parts`` (str, int, float) by BLAKE2b, stable everywhere."""
    h = hashlib.blake2b(digest_size=16, person=b"aptkt-sim")
    for part in parts:
        if isinstance(part, bool) or not isinstance(part, (str, int, float, bytes)):
            raise InvalidTypeError(f"cannot key a seed on {type(part).__name__}")
        if isinstance(part, bytes):
            data, tag = part, b"b"
        elif isinstance(part, str):
            data, tag = part.encode("utf-8"), b"s"
        elif isinstance(part, int):
            data, tag = str(part).encode("ascii"), b"i"
        else:
            data, tag = struct.pack("<d", part), b"f"
        h.update(tag + struct.pack("<I", len(data)) + data)
    return list(struct.unpack("<4I", h.digest()))


def seed_sequence(seed: int, *key: object) -> np.random.SeedSequence:
    """A SeedSequence for ``seed`` and a structured key (e.g. ``("object", "rough_sponge")``)."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidInputError(f"seed must be an integer >= 0, got {seed!r}")
    return np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(seed) >> 32, *stable_words(*key)])


def trial_seed_sequence(
    seed: int, object_name: str, action_name: str, trial: int
) -> np.random.SeedSequence:
    """The root SeedSequence of one trial: everything random in that trial derives from it."""
    return seed_sequence(seed, "trial", object_name, action_name, int(trial))


class CounterStream:
    """Random numbers addressed by ``(sample index, slot)``: a Philox stream with a fixed key.

    Each sample owns ``slots`` consecutive 64-bit words (rounded up to Philox blocks of 4), so
    the numbers of sample ``k`` are the same whether samples are drawn one at a time or in
    bulk. Normal deviates use Box-Muller on pairs of slots (a fixed number of words per
    deviate, unlike numpy's ziggurat).
    """

    def __init__(self, seq: np.random.SeedSequence, slots: int):
        if slots <= 0:
            raise InvalidInputError("slots must be > 0")
        self.slots = int(slots)
        self._blocks = -(-self.slots // 4)  # Philox blocks per sample
        self._key = seq.generate_state(2, dtype=np.uint64)

    @property
    def key(self) -> tuple[int, int]:
        """The Philox key (two 64-bit words) of this stream."""
        return int(self._key[0]), int(self._key[1])

    def raw(self, start: int, count: int) -> np.ndarray:
        """uint64 words of shape ``(count, slots)`` for samples ``start .. start+count``."""
        if count <= 0:
            return np.zeros((0, self.slots), dtype=np.uint64)
        if start < 0:
            raise InvalidInputError("sample index must be >= 0")
        counter = np.zeros(4, dtype=np.uint64)
        counter[0] = np.uint64(start * self._blocks)
        bg = np.random.Philox(key=self._key, counter=counter)
        # Philox increments the counter before generating each block, so block j of this stream
        # is block (start * blocks + j + 1) of the key's sequence: an offset that is the same
        # for every start, hence consistent between chunkings.
        words = bg.random_raw(count * self._blocks * 4)
        return words.reshape(count, self._blocks * 4)[:, : self.slots]

    def uniform(self, start: int, count: int) -> np.ndarray:
        """Uniform deviates in [0, 1), shape ``(count, slots)``."""
        return (self.raw(start, count) >> np.uint64(11)).astype(np.float64) / _TWO53

    def normal(self, start: int, count: int) -> np.ndarray:
        """Standard normal deviates, shape ``(count, slots)`` (slots must be even)."""
        if self.slots % 2:
            raise InvalidInputError("normal() needs an even number of slots")
        u = self.uniform(start, count)
        u1 = 1.0 - u[:, 0::2]  # (0, 1]: log is finite
        u2 = u[:, 1::2]
        r = np.sqrt(-2.0 * np.log(u1))
        out = np.empty_like(u)
        out[:, 0::2] = r * np.cos(2.0 * np.pi * u2)
        out[:, 1::2] = r * np.sin(2.0 * np.pi * u2)
        return out


def spawn_generators(
    seq: np.random.SeedSequence, names: Sequence[str]
) -> dict[str, np.random.Generator]:
    """Independent generators for named purposes; adding a name later does not change the others."""
    return {
        name: np.random.Generator(
            np.random.PCG64(
                np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, *stable_words(name)))
            )
        )
        for name in names
    }
