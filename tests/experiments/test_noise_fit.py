"""The noise fit recovers a known noise level, and ``aptkt dataset fit-noise`` writes it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from aptkt.errors import ConfigError
from aptkt.experiments.noise_fit import (
    NoiseSummary,
    fit_noise,
    next_level,
    simulated_summary,
    summarise,
)
from aptkt.experiments.noise_profile import noise_profile
from aptkt.learning import Observations
from aptkt.sim.noise import NoiseLevel, load_noise_level

N_OBJECTS, N_TRIALS, N_COLUMNS = 30, 30, 8


def _world(level: NoiseLevel, seed: int = 0, n_trials: int = N_TRIALS) -> dict[str, Observations]:
    """A stand-in world whose noise answers to a level as the simulated one does: objects at
    fixed means, a trial's own noise scaled by ``trial`` and by each object's repeatability,
    and a random-walk wander over a run scaled by ``drift``."""
    rng = np.random.default_rng(seed)
    world = np.random.default_rng(1234)  # the objects themselves: the same in every probe
    means = world.normal(0.0, 3.0, size=(N_OBJECTS, N_COLUMNS))
    z = world.normal(size=N_OBJECTS)
    rows, objects, trials = [], [], []
    for o in range(N_OBJECTS):
        sd = level.trial * math.exp(level.objects * z[o])
        walk = np.cumsum(rng.normal(0.0, 0.3, size=(n_trials, N_COLUMNS)), axis=0)
        X = means[o] + sd * rng.normal(size=(n_trials, N_COLUMNS)) + level.drift * walk
        rows.append(X)
        objects += [f"o{o}"] * n_trials
        trials += list(range(n_trials))
    return {"A": Observations("A", {"m": np.vstack(rows)}, np.array(objects), np.array(trials))}


def _probe(level: NoiseLevel, *, trials: int, seed: int, **_: object) -> NoiseSummary:
    return summarise(noise_profile(_world(level, seed=100 + seed, n_trials=trials)), trials)


def test_a_summary_that_meets_the_table_is_a_fixed_point():
    level = NoiseLevel(trial=1.3, drift=0.8, objects=0.4)
    s = NoiseSummary(separation=2.5, drift=1.9, heterogeneity=4.0, trials=30)
    again = next_level(level, s, s)
    assert again.trial == pytest.approx(level.trial)
    assert again.drift == pytest.approx(level.drift)
    assert again.objects == pytest.approx(level.objects)


def test_each_figure_moves_its_own_number_by_its_relation():
    level = NoiseLevel(trial=1.0, drift=1.0, objects=0.0)
    measured = NoiseSummary(separation=4.0, drift=math.sqrt(2.0), heterogeneity=1.0, trials=30)
    # Half the separation: twice the trial noise. Drift² − 1 four times as large: the wander
    # twice as large against the trial noise. Heterogeneity √10 from 1: the object factor adds
    # 3 in the measure's unit, in quadrature.
    target = NoiseSummary(
        separation=2.0, drift=math.sqrt(5.0), heterogeneity=math.sqrt(10), trials=30
    )
    new = next_level(level, measured, target)
    assert new.trial == pytest.approx(2.0)
    assert new.drift / new.trial == pytest.approx(2.0)
    chance = 0.4343 / math.sqrt(2 * 29)
    assert new.objects * math.log10(math.e) / chance == pytest.approx(3.0)


def test_the_fit_recovers_a_known_level():
    truth = NoiseLevel(trial=1.8, drift=1.6, objects=0.5)
    table = _world(truth, seed=7)
    fit = fit_noise(table, probes=5, simulate=_probe)
    assert fit.target.trials == N_TRIALS
    assert fit.level.trial == pytest.approx(truth.trial, rel=0.15)
    assert fit.level.drift == pytest.approx(truth.drift, rel=0.3)
    assert fit.level.objects == pytest.approx(truth.objects, abs=0.15)
    # The fit is the probe closest to the table, and says what it reached.
    assert fit.reached == min((s for _, s in fit.probes), key=lambda s: s.distance(fit.target))
    assert fit.reached.distance(fit.target) < 0.2
    assert fit.probes[0][0] == NoiseLevel()  # it starts from the physical defaults


def test_a_table_that_cannot_be_profiled_is_one_clear_error():
    one_object = {
        "A": Observations("A", {"m": np.zeros((5, 1))}, np.array(["o"] * 5), np.arange(5))
    }
    with pytest.raises(ConfigError, match="no action and modality of the table can be profiled"):
        fit_noise(one_object, simulate=_probe)


def test_a_simulated_probe_answers_to_the_trial_noise():
    """The real probe: a small simulated data set at two levels. Twice the trials' spread
    brings the objects closer in units of the noise."""
    small = dict(trials=8, objects=("rough_sponge", "paper_box", "ceramic_tile", "towel"))
    plain = simulated_summary(NoiseLevel(), actions=("P2",), **small)
    wider = simulated_summary(NoiseLevel(trial=2.0), actions=("P2",), **small)
    assert plain.trials == wider.trials == 8
    assert wider.separation < 0.8 * plain.separation


def test_the_command_writes_a_noise_file_that_generate_reads(tmp_path, monkeypatch, capsys):
    from aptkt import cli
    from aptkt.experiments import noise_fit
    from aptkt.learning.feature_table import write_feature_table

    table = tmp_path / "sensor.csv"
    write_feature_table(table, _world(NoiseLevel(trial=1.5, drift=1.2, objects=0.3), seed=3))
    monkeypatch.setattr(noise_fit, "simulated_summary", _probe)
    out = tmp_path / "noise.toml"
    assert cli.main(["dataset", "fit-noise", str(table), "-o", str(out), "--probes", "4"]) == 0
    said = capsys.readouterr().out
    assert "probe 4/4" in said and f"--noise {out}" in said
    level = load_noise_level(out)
    assert level.trial == pytest.approx(1.5, rel=0.2)
    text = out.read_text()
    assert text.startswith("# aptkt dataset fit-noise") and "[noise]" in text
    # The file is what generate takes, and the data set says which world made it.
    data = tmp_path / "d.h5"
    argv = ["dataset", "generate", "-o", str(data), "--objects", "towel", "--actions", "P2"]
    assert cli.main([*argv, "-n", "2", "-j", "1", "--noise", str(out), "--no-progress"]) == 0
    from aptkt.data import DatasetReader

    with DatasetReader(data) as rd:
        assert rd.description["world_options"]["noise"] == level.to_dict()
    # Completing it in another world is refused, naming both.
    again = [*argv, "-n", "3", "-j", "1", "--noise", "physical", "--resume", "--no-progress"]
    assert cli.main(again) != 0
    err = capsys.readouterr().err
    assert "was generated with the noise level" in err and "mix two worlds" in err


@pytest.mark.parametrize(
    "text, message",
    [
        (None, "noise level file not found"),
        ("[noise\n", "not valid TOML"),
        ("[other]\ntrial = 1\n", "holds a \\[noise\\] table"),
        ("[noise]\ntrial = 1\nloud = 2\n", "unknown noise level field"),
        ("[noise]\ntrial = -1\n", "trial must be a finite number >= 0"),
        ("[noise]\ndrift = 'high'\n", "drift must be a number"),
        ("[noise]\nobjects = true\n", "objects must be a number"),
    ],
)
def test_a_bad_noise_file_is_one_line(tmp_path: Path, text, message):
    path = tmp_path / "noise.toml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_noise_level(path)


def test_a_kept_data_set_of_another_world_is_found(tmp_path):
    """The demo and reproduce keep their simulated data set to reuse it; one simulated at
    another noise level (an older default) is found, so that they simulate it again."""
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.runtime.generation import GenerationPlan, generate, other_world
    from aptkt.sim.noise import FITTED, PHYSICAL

    def plan(noise):
        return GenerationPlan(
            ("towel",), (PAPER_ACTIONS["P2"],), 1, 0, world_options={"noise": noise.to_dict()}
        )

    path = tmp_path / "kept.h5"
    assert other_world(path, plan(FITTED)) is None  # nothing kept yet
    generate(path, plan(PHYSICAL), progress=False)
    assert other_world(path, plan(FITTED)) == PHYSICAL
    assert other_world(path, plan(PHYSICAL)) is None
    (tmp_path / "not.h5").write_bytes(b"not a data set")
    assert other_world(tmp_path / "not.h5", plan(FITTED)) is None


def test_a_kept_data_set_of_another_world_is_simulated_again(tmp_path):
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.data import DatasetReader
    from aptkt.runtime.generation import GenerationPlan, complete_kept, generate
    from aptkt.sim.noise import FITTED, PHYSICAL

    def plan(noise):
        return GenerationPlan(
            ("towel",), (PAPER_ACTIONS["P2"],), 1, 0, world_options={"noise": noise.to_dict()}
        )

    path, said = tmp_path / "kept.h5", []
    generate(path, plan(PHYSICAL), progress=False)
    info = complete_kept(path, plan(FITTED), jobs=1, progress=False, say=said.append)
    assert info["simulated"] == 1 and len(said) == 1 and "simulating it again" in said[0]
    with DatasetReader(path) as rd:
        assert rd.description["world_options"]["noise"] == FITTED.to_dict()
    # In its own world it is reused as it is.
    again = complete_kept(path, plan(FITTED), jobs=1, progress=False, say=said.append)
    assert again["simulated"] == 0 and len(said) == 1


def test_a_table_of_identical_objects_is_one_clear_error():
    rng = np.random.default_rng(0)
    X = np.tile(rng.normal(size=(10, 3)), (3, 1))  # three objects, the same ten trials each
    objects = np.repeat(["a", "b", "c"], 10)
    table = {"A": Observations("A", {"m": X}, objects, np.tile(np.arange(10), 3))}
    with pytest.raises(ConfigError, match="objects do not differ"):
        fit_noise(table, simulate=_probe)
