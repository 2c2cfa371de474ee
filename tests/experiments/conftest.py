"""A quick reproduction of every figure, run once per session (it simulates its own small data
set, ≈ 30 s on 2 cores); the other tests reuse its data set and prior knowledge."""

from __future__ import annotations

import pytest

from aptkt.cli import main


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce-quick")
    assert (
        main(["reproduce", "all", "--quick", "--output", str(out), "--jobs", "2", "--no-progress"])
        == 0
    )
    return out


@pytest.fixture(scope="session")
def quick_data(quick_run):
    (path,) = quick_run.glob("data-quick-seed0.h5")
    return path
