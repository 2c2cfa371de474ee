"""Shared fixtures of the simulation tests: one world, recordings cached per (object, action,
trial) so that tests that look at the same trial do not simulate it twice."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from aptkt.sim import SimWorld
from aptkt.skin.samples import Recording


@pytest.fixture(scope="session")
def world() -> SimWorld:
    return SimWorld(seed=7)


@pytest.fixture(scope="session")
def explore(world: SimWorld) -> Callable[[str, str, int], Recording]:
    cache: dict[tuple[str, str, int], Recording] = {}

    def run(obj: str, action: str, trial: int = 0) -> Recording:
        key = (obj, action, trial)
        if key not in cache:
            cache[key] = world.explore(obj, action, trial)
        return cache[key]

    return run
