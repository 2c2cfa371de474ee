"""The population synthetic objects are drawn from: fitted on a table it recovers the noise and
the spread it was drawn with, matches the table's one-shot accuracy, draws the same objects from
the same seed; the stream's batches; the lifelong benchmark on a stream, from the command line."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.errors import InvalidInputError
from aptkt.experiments.population import ActionPopulation, ObjectPopulation, one_shot_accuracy
from aptkt.experiments.schedule import LARGEST_BATCH, schedule
from aptkt.learning.feature_table import write_feature_table
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import SKIN_EXTRACTION


def _known(d: int = 4, spread: float = 3.0) -> ActionPopulation:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(d, d))
    within = np.eye(d) + 0.3 * (A @ A.T) / d
    return ActionPopulation(
        modalities={"m": 3, "n": d - 3},
        offset=np.arange(d, dtype=float),
        unit=np.linspace(0.5, 2.0, d),
        centre=np.zeros(d),
        between=spread * np.eye(d),
        within=np.linalg.cholesky(within),
        log_level_mean=0.0,
        log_level_sd=0.3,
    )


def _table(pop: ActionPopulation, objects: int, trials: int, seed: int = 0):
    return ObjectPopulation({"A": pop}).draw(objects, trials, seed=seed, prefix="o")


def test_a_fitted_population_has_the_noise_and_the_difficulty_of_its_table():
    truth = _known()
    table = _table(truth, 60, 30)
    fitted = ObjectPopulation.fit(table)
    pop = fitted.actions["A"]
    # The noise in each column's units, and its correlations (W = L Lᵀ in those units).
    W_true = truth.within @ truth.within.T
    W = pop.within @ pop.within.T
    scale = np.sqrt(np.diag(W_true))
    np.testing.assert_allclose(
        W / np.outer(np.sqrt(np.diag(W)), np.sqrt(np.diag(W))),
        W_true / np.outer(scale, scale),
        atol=0.06,
    )
    np.testing.assert_allclose(
        pop.unit / pop.unit[0], truth.unit / truth.unit[0] * scale / scale[0], rtol=0.1
    )
    assert pop.log_level_sd == pytest.approx(0.3, abs=0.12)
    # Drawn objects are told apart by one observation as often as the table's.
    target = fitted.accuracies["A"]
    drawn = [fitted.draw(60, 30, seed=s)["A"] for s in range(3)]
    got = np.mean(
        [
            one_shot_accuracy(
                (np.hstack(list(o.modalities.values())) - pop.offset) / pop.unit,
                o.objects,
                pop.within,
                seed=k,
            )
            for k, o in enumerate(drawn)
        ]
    )
    assert got == pytest.approx(target, abs=0.05)


def test_the_same_seed_draws_the_same_objects_whatever_their_number():
    pop = ObjectPopulation({"A": _known()})
    few, many = pop.draw(3, 5, seed=1)["A"], pop.draw(7, 5, seed=1)["A"]
    np.testing.assert_array_equal(few.modalities["m"], many.modalities["m"][:15])
    assert list(few.objects[:5]) == ["synthetic00000"] * 5
    assert not np.array_equal(pop.draw(3, 5, seed=2)["A"].modalities["m"], few.modalities["m"])
    # More trials of the same objects: the first ones are the same observations.
    longer = pop.draw(3, 8, seed=1)["A"]
    np.testing.assert_array_equal(longer.modalities["m"][:5], few.modalities["m"][:5])


def test_this_skins_logged_columns_are_drawn_as_logarithms():
    rng = np.random.default_rng(0)
    objects = np.repeat(["a", "b", "c"], 10)
    texture = np.exp(rng.normal(size=(30, 4)) + np.repeat([0, 3, 6], 10)[:, None])
    obs = Observations("S1", {"texture": texture}, objects, extraction=SKIN_EXTRACTION)
    pop = ObjectPopulation.fit({"S1": obs}).actions["S1"]
    # Columns 0-2 (activities) were logged: their offsets are on the log scale.
    assert np.all(pop.offset[:3] < np.log10(texture[:, :3]).max())
    drawn = ObjectPopulation({"S1": pop}).draw(2, 3, seed=0)["S1"]
    assert drawn.extraction is None  # z-scored as another sensor's


def test_a_population_needs_objects_and_repeats():
    obs = Observations("A", {"m": np.zeros((2, 1))}, np.array(["a", "b"]))
    with pytest.raises(InvalidInputError, match="at least two objects and repeated"):
        ObjectPopulation.fit({"A": obs})


def test_a_streams_batches_grow_with_the_library_to_the_largest():
    sizes = schedule(1000, 5)
    assert sizes[:4] == [5, 10, 20, 40] and max(sizes) == LARGEST_BATCH
    assert 5 + sum(sizes) == 1000 and len(sizes) < 30
    assert schedule(20, 5) == [5, 10] and schedule(12, 5) == [5]  # a last batch below 5: left out


def test_the_lifelong_benchmark_on_a_stream_reports_cost_per_batch(tmp_path, capsys):
    pop = replace(_known(), between=2.0 * np.eye(4))
    table = write_feature_table(tmp_path / "t.csv", _table(pop, 8, 12))
    out = tmp_path / "stream"
    argv = ["benchmark", "--lifelong", "--from", str(table), "--stream", "24", "--new", "3"]
    argv += ["--orders", "2", "--budget", "2", "-j", "1", "--no-progress", "-o", str(out)]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "a stream of 24 synthetic objects" in said and "batches of 3 to 12 objects" in said
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stream"] == 24 and summary["batch_sizes"] == [3, 6, 12]
    per_batch = summary["results"]
    assert [per_batch[b]["library_size"] for b in ("1", "2", "3")] == [6, 12, 24]
    assert all(per_batch[b]["cpu_seconds"] > 0 and per_batch[b]["memory_mb"] > 0 for b in per_batch)
    assert len(summary["checks"]) == 3
    report = (out / "report.md").read_text()
    assert "synthetic objects per order" in report and "CPU s per batch" in report


@pytest.mark.parametrize(
    "extra, fragment",
    [
        (["--from", "{t}"], "--from: only with --lifelong"),
        (["--lifelong", "--from", "{t}", "{t}"], "give one"),
        (["--lifelong", "{t}", "--stream", "50"], "--stream: only with --from"),
        (["--lifelong", "--from", "{t}", "--stream", "6"], "--stream must be >= 10"),
        (["--lifelong"], "TABLE: give a feature table"),
    ],
)
def test_stream_mistakes_are_one_line(tmp_path, capsys, extra, fragment):
    table = write_feature_table(tmp_path / "t.csv", _table(_known(), 8, 6))
    argv = ["benchmark", *[a.format(t=table) for a in extra], "-o", str(tmp_path / "x")]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("aptkt benchmark: error:") and fragment in err
    assert not (tmp_path / "x").exists()
