"""Sessions and slow drift (aptkt.sim.drift): each effect is there with its designed size,
and a trial's conditions depend only on its own key (seed, session, object, action, trial).
That data sets do not depend on the number of processes is tested with the drift on in
tests/data/test_store.py (the plan's trials 0-2 lie on one run)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.errors import ConfigError
from aptkt.experiments.noise_profile import noise_profile
from aptkt.learning.extract import LM71, observations_from_recordings
from aptkt.sim import RecordingDrift, SimWorld, TrialVariation, Wander, default_library
from aptkt.sim.drift import object_time_constant
from aptkt.sim.noise import PHYSICAL
from aptkt.sim.objects import load_library


def test_a_wanders_trial_uses_only_the_draws_up_to_it():
    wander = Wander(session=0.0, run=0.3, trials=10.0)
    long = wander.path(np.random.default_rng(5), 40, 3)
    short = wander.path(np.random.default_rng(5), 7, 3)
    np.testing.assert_array_equal(long[:7], short)
    # Stationary from the first trial, correlated over about `trials` trials.
    paths = wander.path(np.random.default_rng(1), 4000, 1)[:, 0]
    assert paths.std() == pytest.approx(0.3, rel=0.1)
    lag1 = np.corrcoef(paths[:-1], paths[1:])[0, 1]
    assert lag1 == pytest.approx(np.exp(-1 / 10), abs=0.03)


def test_slow_conditions_depend_only_on_their_key():
    lib, drift = default_library(), RecordingDrift()
    towel = lib["towel"]
    a = drift.at(0, towel, "P1", 12)
    assert drift.at(0, towel, "P1", 12) == a  # after other trials or not
    assert drift.at(1, towel, "P1", 12) != a  # the seed
    assert drift.at(0, towel, "P2", 12) != a  # another action: another run
    assert drift.at(0, towel, "P1", 13) != a  # the run moves on
    assert a.session == "priors" and lib["mouse_pad"].session == "new_objects"
    off = RecordingDrift.off().at(0, towel, "P1", 12)
    assert (off.room, off.force_gain, off.coupling, off.contact) == (0.0, 1.0, 1.0, 1.0)
    assert off.object_lag == 0.0 and np.all(np.array(off.force_offset) == 0.0)


def test_sessions_offset_the_room_and_calibration_and_objects_of_one_session_share_it():
    day_only = dataclasses.replace(
        RecordingDrift.off(),
        room=Wander(session=0.6, run=0.0),
        force_gain=Wander(session=0.03, run=0.0),
        coupling=Wander(session=0.15, run=0.0),
    )
    lib = default_library()
    priors = [day_only.at(0, lib[n], "S1", 3) for n in lib.with_role("prior")]
    new = [day_only.at(0, lib[n], "S1", 3) for n in lib.with_role("new")]
    for group in (priors, new):
        assert len({(c.room, c.force_gain, c.coupling) for c in group}) == 1
    assert priors[0].room != new[0].room and priors[0].force_gain != new[0].force_gain


def test_the_session_offset_reaches_the_readings():
    """The same object recorded in the other session: the skin, warm above a room of another
    temperature, reads the room's offset in free air (its steady state follows the room 1:1)."""
    lib = default_library()
    moved = dataclasses.replace(lib["cork_board"], name="cork_board_later", index=99)
    moved = dataclasses.replace(moved, session="new_objects")
    world = SimWorld(lib.merged([moved]), seed=3)  # a seed whose two sessions' rooms differ
    rooms, lm71 = [], []
    for name in ("cork_board", "cork_board_later"):
        cond = world.conditions(name, "P1", 0)
        rec = world.explore(name, "P1", 0)
        rooms.append(cond.ambient)
        lm71.append(float(rec.samples.temp[:20, LM71].mean()))
    assert abs(rooms[1] - rooms[0]) > 0.4
    assert lm71[1] - lm71[0] == pytest.approx(rooms[1] - rooms[0], abs=0.1)


def test_interface_spread_follows_roughness_and_compliance():
    lib, var = default_library(), TrialVariation()
    spread = {n: var.interface_spread(lib[n]) for n in lib}
    # Rough hard faces (cork's granules, wood's grain) beyond smooth glaze and soft foam.
    for rough in ("cork_board", "wooden_board"):
        for smooth_or_soft in ("ceramic_tile", "rough_sponge", "towel", "padded_case"):
            assert spread[rough] > 2 * spread[smooth_or_soft], (rough, smooth_or_soft)


def test_objects_lag_the_room_and_forget_their_storage():
    lib, drift = default_library(), RecordingDrift()
    # The heavy toolbox takes far longer to follow the room than a sponge.
    assert object_time_constant(lib["metal_toolbox"]) > 10 * object_time_constant(
        lib["rough_sponge"]
    )
    still = dataclasses.replace(RecordingDrift.off(), storage=drift.storage)
    for name, trials_to_forget in (("rough_sponge", 10), ("ceramic_tile", 200)):
        first = abs(still.at(0, lib[name], "C1", 0).object_lag)
        later = abs(still.at(0, lib[name], "C1", trials_to_forget).object_lag)
        assert first > 0.05 and later < 0.05 * first, name
    tile = [still.at(0, lib["ceramic_tile"], "C1", t).object_lag for t in (0, 20, 39)]
    assert abs(tile[0]) > abs(tile[1]) > abs(tile[2]) > 0.1 * abs(tile[0])  # a drift over the run


def test_a_session_name_is_checked(tmp_path):
    path = tmp_path / "mine.toml"
    text = """
[[object]]
name = "slab"
session = "Monday!"
[[object.layer]]
thickness = 0.01
modulus = 1e9
conductivity = 1.0
heat_capacity = 2e6
[object.surface]
friction_static = 0.6
friction_kinetic = 0.5
roughness_rms = 1e-6
contact_conductance = 2000
"""
    path.write_text(text)
    with pytest.raises(ConfigError, match="'session'"):
        load_library(path)
    path.write_text(text.replace('session = "Monday!"\n', ""))
    assert load_library(path)["slab"].session == "custom"  # by default its role's


def _profile(world: SimWorld, objects: list[str], trials: int) -> dict[str, object]:
    action = PAPER_ACTIONS["P2"]
    recordings = [(o, t, world.explore(o, action, t)) for o in objects for t in range(trials)]
    table = {"P2": observations_from_recordings(action, recordings)}
    return {p.modality: p for p in noise_profile(table)}


@pytest.mark.slow
def test_drift_and_unequal_noise_on_a_generated_table():
    """Firm presses (P2) on every object, 24 trials each, with the drift and without: the drift
    index near the real sensor's (≈ 2) against stationary noise's 1, and the thermal noise
    unequal between objects (measured: force 1.8, thermal 2.1 against 1.1 and 1.2 without;
    thermal heterogeneity 1.7 against 1.2). Both at the physical noise level: the default's
    fitted object factor (aptkt.sim.noise) makes the noise unequal by itself."""
    library = default_library()
    objects = list(library)
    drifting = _profile(SimWorld(library, seed=0, noise=PHYSICAL), objects, 24)
    still = _profile(
        SimWorld(library, seed=0, drift=RecordingDrift.off(), noise=PHYSICAL), objects, 24
    )
    for modality in ("force", "thermal"):
        assert drifting[modality].drift > 1.5, modality
        assert still[modality].drift < 1.3, modality
    assert drifting["thermal"].heterogeneity > 1.5
    assert drifting["thermal"].heterogeneity > 1.3 * still["thermal"].heterogeneity
