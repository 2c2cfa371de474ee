"""The bounded sample buffer against a plain list model."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.skin.ring import SampleRing
from aptkt.skin.samples import FIELDS, SkinSamples


def batch(start: int, n: int) -> SkinSamples:
    t = np.arange(start, start + n, dtype=np.int64)
    return SkinSamples(
        cell_id=(t % 7 + 1).astype(np.uint16),
        t_ns=t,
        proximity=t * 0.5,
        acc=np.stack([t, -t, 2 * t], axis=1).astype(float),
        temp=np.stack([t, t + 1], axis=1).astype(float),
        force=np.stack([t, t, t], axis=1).astype(float),
    )


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 20), st.lists(st.one_of(st.integers(0, 30), st.just(-1)), max_size=30))
def test_ring_matches_a_bounded_list(capacity, ops):
    ring = SampleRing(capacity)
    model: list[int] = []
    dropped = 0
    counter = 0
    for op in ops:
        if op < 0:
            got = ring.drain()
            assert got.t_ns.tolist() == model
            for name in FIELDS:
                np.testing.assert_array_equal(
                    getattr(got, name),
                    getattr(batch(0, 10**4).take(np.array(model, dtype=int)), name),
                )
            model = []
        else:
            ring.push(batch(counter, op))
            model.extend(range(counter, counter + op))
            counter += op
            if len(model) > capacity:
                dropped += len(model) - capacity
                model = model[-capacity:]
        assert len(ring) == len(model) and ring.overflows == dropped


def test_capacity_must_be_positive():
    with pytest.raises(ValueError):
        SampleRing(0)
