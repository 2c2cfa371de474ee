"""The world's noise level scales exactly what it says, and nothing else."""

from __future__ import annotations

import math
from dataclasses import asdict, fields

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aptkt.errors import InvalidInputError
from aptkt.sim.drift import RecordingDrift, Wander
from aptkt.sim.noise import (
    FITTED,
    PHYSICAL,
    TRIAL_SPREADS,
    NoiseLevel,
    load_noise_level,
    noise_level_toml,
)
from aptkt.sim.trial import TrialVariation
from aptkt.sim.world import SimWorld

scale = st.floats(min_value=0.0, max_value=4.0, allow_nan=False)
spread = st.floats(min_value=0.0, max_value=2.0, allow_nan=False)


@given(k=scale)
def test_the_trial_number_multiplies_every_spread_and_only_the_spreads(k):
    base = TrialVariation()
    scaled = NoiseLevel(trial=k).variation(base, seed=0, object_name="towel")
    for name, value in asdict(base).items():
        expected = value * k if name in TRIAL_SPREADS else value
        assert getattr(scaled, name) == pytest.approx(expected, rel=1e-12, abs=0.0), name


def test_every_spread_of_a_trial_is_named():
    """A spread added to TrialVariation must be scaled too: every field is either a spread
    or one of the levels and constants named here."""
    levels = {"ambient", "conformity_roughness", "cover_modulus", "arm_vibration"}
    assert {f.name for f in fields(TrialVariation)} == set(TRIAL_SPREADS) | levels


@given(k=scale)
def test_the_drift_number_multiplies_every_wander_and_the_storage(k):
    base = RecordingDrift()
    scaled = NoiseLevel(drift=k).recording_drift(base)
    for f in fields(base):
        old, new = getattr(base, f.name), getattr(scaled, f.name)
        if isinstance(old, Wander):
            assert new.session == pytest.approx(old.session * k, abs=0.0, rel=1e-12)
            assert new.run == pytest.approx(old.run * k, abs=0.0, rel=1e-12)
            assert new.trials == old.trials
        elif f.name == "storage":
            assert new == pytest.approx(old * k, abs=0.0, rel=1e-12)
        else:
            assert new == old, f.name


def test_an_objects_repeatability_is_log_normal_with_the_given_spread():
    level = NoiseLevel(objects=0.4)
    logs = np.log([level.repeatability(3, f"object {i}") for i in range(4000)])
    assert logs.mean() == pytest.approx(0.0, abs=3 * 0.4 / math.sqrt(4000))
    assert logs.std() == pytest.approx(0.4, rel=0.05)
    # Keyed by the world's seed and the object: the same object is the same in every process.
    assert level.repeatability(3, "towel") == level.repeatability(3, "towel")
    assert level.repeatability(3, "towel") != level.repeatability(4, "towel")
    assert NoiseLevel(objects=0.0).repeatability(3, "towel") == 1.0


def test_a_world_at_twice_the_trial_noise_moves_each_trial_twice_as_far():
    """The same draws, scaled: the object's shift from its nominal spot is exactly doubled."""
    one = SimWorld(seed=0, noise=PHYSICAL).conditions("towel", "P2", 5)
    two = SimWorld(seed=0, noise=NoiseLevel(trial=2.0)).conditions("towel", "P2", 5)
    assert two.shift == pytest.approx(tuple(2 * s for s in one.shift), rel=1e-12)
    assert two.depth_error == pytest.approx(2 * one.depth_error, rel=1e-12)


def test_the_physical_level_is_the_world_of_the_physical_defaults():
    plain = SimWorld(seed=0, noise=PHYSICAL)
    assert plain.drift == RecordingDrift()
    assert plain.conditions("towel", "S1", 2) == SimWorld(seed=0, noise={}).conditions(
        "towel", "S1", 2
    )
    assert SimWorld(seed=0).noise == FITTED


@settings(max_examples=50)
@given(trial=scale, drift=scale, objects=spread)
def test_a_noise_file_reads_back_what_was_written(tmp_path_factory, trial, drift, objects):
    level = NoiseLevel(trial=trial, drift=drift, objects=objects)
    path = tmp_path_factory.mktemp("noise") / "noise.toml"
    path.write_text(noise_level_toml(level, ("a comment",)))
    back = load_noise_level(path)
    for name in ("trial", "drift", "objects"):
        assert getattr(back, name) == pytest.approx(getattr(level, name), abs=5e-5)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -0.1])
def test_a_level_that_is_no_scale_is_refused(bad):
    with pytest.raises(InvalidInputError, match="must be a finite number >= 0"):
        NoiseLevel(trial=bad)
    with pytest.raises(InvalidInputError, match="unknown noise level field"):
        SimWorld(seed=0, noise={"loudness": 1.0})


def test_a_level_beyond_the_worlds_range_is_refused_and_the_fit_stays_within_it():
    from aptkt.experiments.noise_fit import NoiseSummary, next_level
    from aptkt.sim.noise import MAX_LEVEL

    with pytest.raises(InvalidInputError, match="noise level trial 5 is above its largest, 4"):
        NoiseLevel(trial=5.0)
    # A table far noisier than the world can be: the nearest level, not an error.
    measured = NoiseSummary(separation=4.0, drift=1.1, heterogeneity=1.0, trials=30)
    hopeless = NoiseSummary(separation=0.1, drift=50.0, heterogeneity=400.0, trials=30)
    level = next_level(NoiseLevel(), measured, hopeless)
    assert level.to_dict() == MAX_LEVEL


def test_the_docs_quote_the_default_level_and_the_largest_ones():
    from pathlib import Path

    from aptkt.sim.noise import MAX_LEVEL

    page = (Path(__file__).resolve().parents[2] / "docs" / "simulation.md").read_text()
    fit = FITTED.to_dict()
    row = f"| **{fit['trial']:.3f}** | **{fit['drift']:.3f}** | **{fit['objects']:.3f}** |"
    assert row in page
    largest = ", ".join(f"{k} {v:g}" for k, v in MAX_LEVEL.items())
    assert f"`MAX_LEVEL`: {largest};" in page
