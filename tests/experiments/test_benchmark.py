"""The real-data benchmark on a small synthetic feature table: the protocol (splits, prior
choices, pairing), the numbers it reports against recomputations from its own results, the
checks, and its command line."""

from __future__ import annotations

import csv
import json
from collections import defaultdict

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.experiments import benchmark_report as br
from aptkt.experiments.benchmark import (
    BenchmarkSettings,
    object_distances,
    prior_choices,
    split_trials,
)
from aptkt.learning import Observations
from aptkt.learning.feature_table import read_feature_table, write_feature_table

N_OBJECTS, N_TRIALS = 8, 8


def _table(tmp_path, suffix=".csv"):
    """8 objects on a line in one modality (object k at 3k), noise 1, one action; a second
    modality of pure noise."""
    rng = np.random.default_rng(0)
    objects = np.repeat([f"o{k}" for k in range(N_OBJECTS)], N_TRIALS)
    centre = np.repeat(3.0 * np.arange(N_OBJECTS), N_TRIALS)
    shape = np.column_stack([centre, np.zeros_like(centre)]) + rng.normal(size=(objects.size, 2))
    noise = rng.normal(size=(objects.size, 1))
    trials = np.tile(np.arange(N_TRIALS), N_OBJECTS)
    obs = Observations("touch", {"shape": shape, "noise": noise}, objects, trials)
    return write_feature_table(tmp_path / f"table{suffix}", {"touch": obs})


def test_each_object_learns_from_its_first_half_and_is_tested_on_its_second(tmp_path):
    table = read_feature_table(_table(tmp_path))
    learn, test = split_trials(table, ["touch"])
    assert learn.sum() == test.sum() == N_OBJECTS * N_TRIALS // 2
    for obj in table.object_names:
        rows = table.rows_of(obj, "touch")
        assert set(table.trials[rows[learn[rows]]]) == {0, 1, 2, 3}
        assert set(table.trials[rows[test[rows]]]) == {4, 5, 6, 7}


def test_priors_are_chosen_at_random_nearest_and_farthest_by_noise_levels(tmp_path):
    table = read_feature_table(_table(tmp_path))
    learn, _ = split_trials(table, ["touch"])
    names, d = object_distances(table.observations(["touch"], learn))
    # Objects 3 apart in units of noise 1 (the noise column adds a little).
    i, j = names.index("o0"), names.index("o1")
    assert 2.0 < d[i, j] < 4.5 and d[i, j] < d[i, names.index("o5")]
    new = ["o0", "o1"]
    rest = [f"o{k}" for k in range(2, N_OBJECTS)]
    got = prior_choices(new, rest, 2, (names, d), np.random.default_rng(0))
    assert got["nearest"] == ("o2", "o3") and got["farthest"] == ("o6", "o7")
    assert len(set(got["random"])) == 2 and set(got["random"]) <= set(rest)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    table = _table(out)
    argv = ["benchmark", str(table), "-o", str(out / "b"), "--groups", "3", "--new", "3"]
    argv += ["--priors", "2", "--budget", "2", "-j", "1", "--no-progress"]
    assert main(argv) == 0
    return out / "b"


def _rows(path):
    with open(path / "results.csv") as fh:
        return list(csv.DictReader(fh))


def test_every_method_runs_for_every_group_and_prior_choice(run):
    rows = _rows(run)
    runs = defaultdict(list)
    for r in rows:
        runs[(r["group"], r["priors"], r["method"])].append(int(r["step"]))
    assert {k[1] for k in runs} == {"random", "nearest", "farthest"}
    assert {k[2] for k in runs} == {"baseline", "APTKT", "APTKT+aux", "control", "1-NN"}
    assert len(runs) == 3 * 3 * 5
    for (_, _, method), steps in runs.items():
        assert sorted(steps) == ([0] if method == "1-NN" else [0, 1, 2])
    # The baseline uses no prior: one run serves all three choices of a group.
    for g in ("0", "1", "2"):
        curves = {r["priors"]: [] for r in rows if r["group"] == g and r["method"] == "baseline"}
        for r in rows:
            if r["group"] == g and r["method"] == "baseline":
                curves[r["priors"]].append(r["accuracy"])
        assert len({tuple(v) for v in curves.values()}) == 1


def test_the_reported_gains_are_the_paired_means_of_the_results(run):
    rows = _rows(run)
    summary = json.loads((run / "summary.json").read_text())
    for choice in ("random", "nearest", "farthest"):
        acc = defaultdict(dict)
        for r in rows:
            if r["priors"] == choice and r["step"] == "0":
                acc[r["method"]][r["group"]] = float(r["accuracy"])
        d = [acc["APTKT"][g] - acc["baseline"][g] for g in sorted(acc["APTKT"])]
        gain = summary["results"][choice]["gain"]["APTKT"][0]
        assert gain["mean"] == pytest.approx(np.mean(d))
        half = 4.303 * np.std(d, ddof=1) / np.sqrt(3)  # Student's t, 2 degrees of freedom
        assert gain["high"] - gain["mean"] == pytest.approx(half)
        assert gain["n"] == 3 and gain["unit"] == "groups"
    report = (run / "report.md").read_text()
    assert "## Checks" in report and "1-NN" in report
    assert (run / "benchmark.png").stat().st_size > 0 and (run / "benchmark.svg").exists()
    assert "## How the data's noise looks" in report and len(summary["noise_profile"]) == 2
    assert summary["learner"]["gp"]["kernel"] == "shared"


def test_the_nearest_neighbour_reference_is_the_plain_rule(run):
    """1-NN on the first observation of each new object, in the prior's space, recomputed
    from the learner's own one-shot observations is what the results hold."""
    from aptkt.experiments.benchmark import _subset, nearest_neighbour_accuracy
    from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge

    rows = _rows(run)
    table = read_feature_table(run.parent / "table.csv")
    learn_rows, test_rows = split_trials(table, ["touch"])
    learn = table.observations(["touch"], learn_rows)
    test = table.observations(["touch"], test_rows)
    r0 = next(r for r in rows if r["method"] == "1-NN" and r["group"] == "0")
    new, priors = r0["new_objects"].split(","), r0["prior_objects"].split(",")
    seed = 0  # the benchmark's seed for group 0 with --seed 0
    base = APTKT(LearnerConfig(transfer="none", budget=0, seed=seed))
    base.run(PoolEnvironment(_subset(learn, new), seed=seed), ["touch"], new)
    first = {"touch": base.learners["touch"].observations}
    prior = PriorKnowledge.build(_subset(learn, priors))
    expected = nearest_neighbour_accuracy(prior, first, _subset(test, new))
    X = prior["touch"].pipeline.transform(first["touch"])[0]
    T = prior["touch"].pipeline.transform(_subset(test, new)["touch"])[0]
    nearest = first["touch"].objects[
        np.argmin(((T[:, None, :] - X[None, :, :]) ** 2).sum(-1), axis=1)
    ]
    assert expected == pytest.approx(np.mean(nearest == _subset(test, new)["touch"].objects))
    assert float(r0["accuracy"]) == pytest.approx(expected)


def _curves(base, aptkt, aux=None, nn=0.5, falls=False):
    n = 6
    rng = np.random.default_rng(1)
    steps = np.arange(4)
    c = {
        "baseline": np.tile(base + 0.02 * steps, (n, 1)) + 0.001 * rng.normal(size=(n, 4)),
        "APTKT": np.tile(aptkt + 0.02 * steps, (n, 1)) + 0.001 * rng.normal(size=(n, 4)),
        "control": np.tile(aptkt + 0.02 * steps, (n, 1)),
        "1-NN": np.full((n, 1), nn),
    }
    c["APTKT+aux"] = c["APTKT"] + (0.0 if aux is None else aux)
    if falls:
        c["baseline"][:, 2] -= 0.05
    return {"random": c, "farthest": {k: v.copy() for k, v in c.items()}}


@pytest.mark.parametrize(
    "curves, failing",
    [
        (_curves(0.6, 0.75), []),
        (_curves(0.6, 0.65), ["baseline + 10 pp"]),
        (_curves(0.6, 0.75, nn=0.8), ["nearest-neighbour"]),
        (_curves(0.6, 0.55), ["baseline + 10 pp", "least similar"]),
        (_curves(0.6, 0.75, aux=-0.01), ["auxiliary"]),
        (_curves(0.6, 0.75, falls=True), ["unlearns"]),
    ],
)
def test_each_check_fails_exactly_when_its_claim_does(curves, failing):
    found = br.checks(curves)
    assert len(found) == 5
    failed = [k.claim for k in found if not k.holds]
    assert len(failed) == len(failing), failed
    for fragment in failing:
        assert any(fragment in claim for claim in failed), (fragment, failed)


def test_the_command_refuses_to_overwrite_and_reports_mistakes_in_one_line(run, tmp_path, capsys):
    table = run.parent / "table.csv"
    argv = ["benchmark", str(table), "-o", str(run), "--groups", "2"]
    assert main(argv) == 1
    assert "--force" in capsys.readouterr().err
    for extra, fragment in (
        (["--new", "1"], "--new must be >= 2"),
        (["--choices", "closest"], "--choices: closest"),
        (["--groups", "0"], "--groups must be >= 1"),
        # bounded as the other commands' counts (docs/reliability.md)
        (["--groups", "1000000"], "--groups must be at most 1000"),
        (["--budget", "1000000000"], "--budget must be at most 10000"),
        (["-j", "100000"], "--jobs must be at most"),
    ):
        assert main(["benchmark", str(table), "-o", str(tmp_path / "x"), *extra]) == 1
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("aptkt benchmark: error:"), err
        assert fragment in err
    assert (
        main(["benchmark", str(table), "-o", str(tmp_path / "y"), "--new", "6", "--priors", "3"])
        == 1
    )
    assert "need at least 9 objects" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    assert BenchmarkSettings().groups == 60
