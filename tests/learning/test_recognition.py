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
