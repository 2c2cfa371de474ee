"""Recognising what the library knows and flagging what it does not: the fused posterior
against a direct computation, the threshold chosen on the library, the command line and its
mistakes."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from scipy.special import logsumexp

from aptkt.cli import main
from aptkt.learning import PriorKnowledge
from aptkt.learning.feature_table import write_feature_table
from aptkt.learning.observations import Observations
from aptkt.learning.recognition import auroc, calibrate

MEANS = {f"o{k}": np.array([6.0 * k, 0.0, 3.0 * (k % 2)]) for k in range(5)}
UNSEEN = {"u0": np.array([40.0, 30.0, -20.0]), "u1": np.array([-30.0, 25.0, 12.0])}


def _obs(means, n, seed, action="A", first_trial=0):
    rng = np.random.default_rng(seed)
    names = np.repeat(list(means), n)
    X = np.array([means[o] for o in names]) + rng.normal(size=(names.size, 3))
    trials = np.tile(np.arange(first_trial, first_trial + n), len(means))
    return Observations(action, {"m": X[:, :1], "q": X[:, 1:]}, names, trials)


@pytest.fixture(scope="module")
def library():
    return PriorKnowledge.build({"A": _obs(MEANS, 12, 0), "B": _obs(MEANS, 12, 1, "B")}, seed=0)


def test_a_touch_fuses_its_actions_as_independent_evidence(library):
    """Two actions on the same object and trial are one touch: its posterior is the one of the
    summed per-action log-likelihoods, computed here from the identity models directly."""
    touch = {"A": _obs(MEANS, 1, 5), "B": _obs(MEANS, 1, 6, "B")}
    result = library.recognise(touch)
    assert len(result) == len(MEANS) and set(result.actions) == {"A+B"}
    objects = library.objects
    for k, name in enumerate(result.object):
        old = np.zeros(len(objects))
        new = 0.0
        for action, obs in touch.items():
            ap = library[action]
            row = np.flatnonzero(obs.objects == name)
            o, n = ap.identity.log_likelihoods(ap.pipeline.transform(obs)[0][row])
            old += o
            new += n
        joint = np.concatenate([[np.log(0.5) + new], np.log(0.5 / len(objects)) + old])
        joint -= logsumexp(joint)
        assert result.novelty[k] == pytest.approx(joint[0] - logsumexp(joint[1:]), abs=1e-9)
        assert result.predicted[k] == objects[int(np.argmax(joint[1:]))]
        p = np.exp(joint[1:] - logsumexp(joint[1:]))
        assert result.probability[k] == pytest.approx(p.max())
        assert result.runner_up[k] == objects[int(np.argsort(-p)[1])]
    assert result.accuracy() == 1.0


def test_known_objects_are_known_and_new_ones_are_flagged(library):
    test = {
        a: Observations.concat([_obs(MEANS, 6, 7, a, 100), _obs(UNSEEN, 6, 8, a, 100)])
        for a in "AB"
    }
    result = library.recognise(test)
    mine = result.in_library()
    assert result.accuracy() > 0.9
    assert np.mean(result.known[mine]) > 0.8 and not result.known[~mine].any()
    assert result.novelty_auroc() == pytest.approx(1.0)
    rows = result.rows()
    assert set(rows[0]) == {
        "object",
        "action",
        "trial",
        "predicted",
        "probability",
        "runner_up",
        "novelty",
        "known",
    }
    assert result.columns()["object"] == result.object


def test_the_threshold_is_chosen_on_the_library_for_its_false_alarm_rate(library):
    """The threshold is the (1 − rate) quantile of the library's touches scored without them:
    raising the rate lowers it, and about that share of the library's own touches lie above."""
    low, high = calibrate(library, 0.02), calibrate(library, 0.3)
    assert high.threshold < low.threshold
    assert 0.0 <= low.detection_rate <= 1.0 and low.touches == 5 * 12
    with pytest.raises(ValueError):
        calibrate(library, 0.0)


def test_auroc_is_the_mann_whitney_statistic():
    rng = np.random.default_rng(0)
    a, b = rng.normal(1, 1, 40), rng.normal(0, 1, 30)
    from sklearn.metrics import roc_auc_score

    ref = roc_auc_score(np.r_[np.ones(40), np.zeros(30)], np.r_[a, b])
    assert auroc(a, b) == pytest.approx(ref)
    assert auroc(np.array([1.0]), np.array([1.0])) == 0.5


def _write(path, table):
    return write_feature_table(path, table)


def test_recognise_on_the_command_line(library, tmp_path, capsys):
    lib = library.save(tmp_path / "lib.npz")
    # A library built from a table records its columns; a table's touches are recognised.
    train = _write(tmp_path / "train.csv", {"A": _obs(MEANS, 12, 0)})
    assert main(["prior", "build", str(train), "-o", str(tmp_path / "t.npz")]) == 0
    capsys.readouterr()
    test = _write(
        tmp_path / "test.csv", {"A": Observations.concat([_obs(MEANS, 4, 3), _obs(UNSEEN, 4, 4)])}
    )
    out = tmp_path / "r"
    assert (
        main(
            ["recognise", "--prior", str(tmp_path / "t.npz"), "--table", str(test), "-o", str(out)]
        )
        == 0
    )
    said = capsys.readouterr().out
    assert "novelty AUROC 1.000" in said
    with open(out / "predictions.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * 7 and set(rows[0]) >= {
        "object",
        "action",
        "trial",
        "predicted",
        "probability",
        "runner_up",
        "novelty",
        "known",
    }
    summary = json.loads((out / "summary.json").read_text())
    assert summary["novelty_auroc"] == 1.0 and (out / "confusion.png").stat().st_size > 0
    # What became of each touch, recounted from predictions.csv: shares that add up to one.
    known = [r for r in rows if r["object"] in summary["library"]]
    accepted = [r for r in known if r["known"] == "True"]
    mine = summary["library_objects"]
    assert mine["touches"] == len(known)
    assert mine["accepted_and_right"] == pytest.approx(
        sum(r["predicted"] == r["object"] for r in accepted) / len(known)
    )
    assert mine["flagged_new"] == pytest.approx(1 - len(accepted) / len(known))
    assert sum(v for k, v in mine.items() if k != "touches") == pytest.approx(1.0)
    other = summary["other_objects"]
    assert other["flagged_new"] + other["accepted_as_a_library_object"] == pytest.approx(1.0)
    assert f"{mine['touches']} touch(es) of objects in the library: " in said
    assert "accepted and right" in said and "accepted as a library object" in said
    assert main(["recognise", "--prior", str(lib), "--table", str(test), "-o", str(out)]) == 1
    assert "--force" in capsys.readouterr().err


def test_recognise_mistakes_are_one_line(library, tmp_path, capsys):
    train = _write(tmp_path / "train.csv", {"A": _obs(MEANS, 12, 0)})
    assert main(["prior", "build", str(train), "-o", str(tmp_path / "t.npz")]) == 0
    capsys.readouterr()
    other = {
        "A": Observations(
            "A", {"m": np.zeros((4, 1)), "z": np.ones((4, 2))}, np.array(["o0"] * 4), np.arange(4)
        )
    }
    wrong = _write(tmp_path / "wrong.csv", other)
    foreign = _write(tmp_path / "foreign.csv", {"C": _obs(MEANS, 2, 0, "C")})
    bad_lib = tmp_path / "bad.npz"
    bad_lib.write_bytes(b"not a zip")
    cases = (
        (["--table", str(wrong)], "missing q.0, q.1; extra z.0, z.1"),
        (["--table", str(foreign)], "none of its actions"),
        (["--table", str(tmp_path / "none.csv")], "none.csv"),
        (["--table", str(train), "--false-alarm-rate", "2"], "--false-alarm-rate"),
    )
    for extra, fragment in cases:
        assert (
            main(
                ["recognise", "--prior", str(tmp_path / "t.npz"), *extra, "-o", str(tmp_path / "x")]
            )
            == 1
        )
        err = capsys.readouterr().err.strip()
        assert err.startswith("aptkt recognise: error:") and err.count("\n") == 0, err
        assert fragment in err, err
    assert (
        main(
            ["recognise", "--prior", str(bad_lib), "--table", str(train), "-o", str(tmp_path / "x")]
        )
        == 1
    )
    assert "not a prior-knowledge file" in capsys.readouterr().err
    assert not (tmp_path / "x" / "predictions.csv").exists()


@pytest.fixture(scope="module")
def touches(tmp_path_factory):
    """A library built from a table, the touches of its objects (trials 0-7) as CSV and as an
    HDF5 table, and a small data set of this skin."""
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.runtime.generation import GenerationPlan, generate

    d = tmp_path_factory.mktemp("touches")
    train = _write(d / "train.csv", {"A": _obs(MEANS, 12, 0)})
    assert main(["prior", "build", str(train), "-o", str(d / "lib.npz")]) == 0
    _write(d / "touches.csv", {"A": _obs(MEANS, 8, 3), "C": _obs(MEANS, 2, 4, "C", 20)})
    _write(d / "touches.h5", {"A": _obs(MEANS, 8, 3)})
    plan = GenerationPlan(("rough_sponge", "metal_toolbox"), (PAPER_ACTIONS["P1"],), 3, seed=3)
    generate(d / "d.h5", plan, progress=False)
    return d


def _predictions(out):
    with open(out / "predictions.csv") as fh:
        return list(csv.DictReader(fh))


def test_the_touches_are_given_as_dataset_or_table_whatever_the_file(touches, tmp_path, capsys):
    """One input, DATASET|TABLE, told apart by what the file is; --table, the earlier spelling,
    gives the same predictions."""
    lib = str(touches / "lib.npz")
    runs = {
        "csv": [str(touches / "touches.csv")],
        "h5": [str(touches / "touches.h5")],
        "--table": ["--table", str(touches / "touches.csv")],
    }
    for name, given in runs.items():
        assert main(["recognise", "--prior", lib, *given, "-o", str(tmp_path / name)]) == 0
    capsys.readouterr()
    rows = {name: _predictions(tmp_path / name) for name in runs}
    assert len(rows["csv"]) == 5 * 8
    assert rows["csv"] == rows["--table"] == rows["h5"]
    summary = json.loads((tmp_path / "csv" / "summary.json").read_text())
    assert summary["input"] == runs["csv"][0] and summary["trials"] is None


def test_trials_chooses_exactly_those_touches(touches, tmp_path, capsys):
    lib = str(touches / "lib.npz")
    table = str(touches / "touches.csv")
    assert (
        main(["recognise", "--prior", lib, table, "--trials", "3-4", "-o", str(tmp_path / "t")])
        == 0
    )
    rows = _predictions(tmp_path / "t")
    assert len(rows) == 5 * 2 and {r["trial"] for r in rows} == {"3", "4"}
    assert json.loads((tmp_path / "t" / "summary.json").read_text())["trials"] == "3-4"
    # The same selection on a data set of this skin, recognised with a library built from it.
    data = str(touches / "d.h5")
    assert main(["prior", "build", data, "-o", str(tmp_path / "d.npz")]) == 0
    out = tmp_path / "d"
    assert (
        main(
            [
                "recognise",
                "--prior",
                str(tmp_path / "d.npz"),
                data,
                "--trials",
                "0,2",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    rows = _predictions(out)
    assert len(rows) == 2 * 2 and {r["trial"] for r in rows} == {"0", "2"}


def _one_error_line(argv, capsys, label="aptkt recognise"):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{label}: error: "), err
    return lines[0]


def test_a_file_of_the_wrong_kind_is_one_line_saying_what_to_write(touches, tmp_path, capsys):
    lib, table, data = (str(touches / n) for n in ("lib.npz", "touches.csv", "d.h5"))
    out = ["-o", str(tmp_path / "x")]
    learn = ["--prior-objects", "o0,o1", "--objects", "o2,o3", *out]
    cases = [
        # a data set where only a feature table is read: the command that writes its table
        (
            ["learn", data, *learn],
            "aptkt learn",
            f"aptkt dataset export-features {data} -o {data[:-3]}.csv",
        ),
        (["learn", "--table", data, *learn], "aptkt learn", "aptkt dataset export-features"),
        (["benchmark", data, *out], "aptkt benchmark", "aptkt dataset export-features"),
        # a feature table where only a data set is read
        (
            ["dataset", "features", table],
            "aptkt dataset features",
            "is a feature table, not a data set",
        ),
        # the library as the touches
        (["recognise", "--prior", lib, lib, *out], "aptkt recognise", "give it with --prior"),
        (
            ["recognise", "--prior", lib, str(touches / "none.csv"), *out],
            "aptkt recognise",
            "no such data set or feature table",
        ),
        (["recognise", "--prior", lib, *out], "aptkt recognise", "--prior PRIOR DATASET|TABLE"),
        (
            ["recognise", "--prior", lib, table, "--table", table, *out],
            "aptkt recognise",
            "give the touches once",
        ),
    ]
    for argv, label, fragment in cases:
        assert fragment in _one_error_line(argv, capsys, label)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("trials", "fragment"),
    [
        ("x", "--trials x: 'x' is not a trial number or a range"),
        ("-3", "'-3' is not a trial number or a range"),
        ("1,,2", "an empty item is not a trial number"),
        ("", "--trials: give trial numbers and ranges"),
        ("4-3", "the range 4-3 runs backwards (write 3-4)"),
        ("5:5", "5:5 holds no trial"),
        ("3-40", "--trials 3-40: trial(s) 8-19,22-40 not in"),
        ("40-50", "--trials 40-50: not in"),
        ("20-21", "no touches of the library's actions in these trials"),
    ],
)
def test_bad_trials_are_one_line(touches, tmp_path, capsys, trials, fragment):
    lib, table = str(touches / "lib.npz"), str(touches / "touches.csv")
    line = _one_error_line(
        ["recognise", "--prior", lib, table, "--trials", trials, "-o", str(tmp_path / "x")], capsys
    )
    assert fragment in line, line
    if "not in" in fragment:
        assert line.endswith("(it has trials 0-7,20-21)"), line
