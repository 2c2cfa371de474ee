"""``aptkt collect`` and ``aptkt learn`` with ``--robot sim``: the robot-independent plumbing
(plans, resume, the data set, the live learner's outputs) without ur_rtde."""

from __future__ import annotations

import csv
import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from aptkt.actions import actions_from_toml
from aptkt.cli import main
from aptkt.data import DatasetReader
from aptkt.errors import ProtectiveStopError, TrialFault
from aptkt.learning import LearnerConfig, PriorKnowledge
from aptkt.learning.dataset import load_observations
from aptkt.runtime.live_learning import LiveLearningAborted, learn_live
from aptkt.runtime.sessions import SimSession

ACTIONS_TOML = """
[[action]]
name = "Pq"
movement = "press"
depth = 0.001
hold_time = 0.5

[[action]]
name = "Sq"
movement = "slide"
normal_force = 0.2
speed = 0.02
slide_time = 0.5
"""
PRIORS = "rough_sponge,paper_box,metal_toolbox"
NEW = "smooth_sponge,hard_box"


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("cli_sim")
    (d / "actions.toml").write_text(ACTIONS_TOML)
    return d


def collect(workdir: Path, *args: str) -> int:
    return main(
        [
            "collect",
            "--robot",
            "sim",
            "--actions-file",
            str(workdir / "actions.toml"),
            "--thermal-wait",
            "0",
            "--no-progress",
            *args,
        ]
    )


@pytest.fixture(scope="module")
def prior(workdir: Path) -> Path:
    data = workdir / "prior.h5"
    assert (
        collect(workdir, "--objects", PRIORS, "--actions", "Pq,Sq", "-n", "4", "-o", str(data)) == 0
    )
    path = workdir / "prior.npz"
    PriorKnowledge.build(load_observations(data)).save(path)
    return path


def learn(workdir: Path, prior: Path, out: Path, *args: str) -> int:
    return main(
        [
            "learn",
            "--robot",
            "sim",
            "--prior",
            str(prior),
            "--actions-file",
            str(workdir / "actions.toml"),
            "--thermal-wait",
            "0",
            "-o",
            str(out),
            *args,
        ]
    )


def test_collect_writes_every_trial_and_resume_adds_only_the_missing_ones(workdir: Path, capsys):
    out = workdir / "a.h5"
    assert (
        collect(
            workdir, "--objects", "towel,cork_board", "--actions", "Pq", "-n", "2", "-o", str(out)
        )
        == 0
    )
    with DatasetReader(out) as rd:
        assert sorted(rd.keys()) == [(o, "Pq", t) for o in ("cork_board", "towel") for t in (0, 1)]
        first = {rd.key(i): rd.raw(i) for i in range(len(rd))}
        assert rd.description["session"]["robot"] == "sim"
    capsys.readouterr()
    assert (
        collect(
            workdir,
            "--objects",
            "towel,cork_board",
            "--actions",
            "Pq",
            "-n",
            "3",
            "-o",
            str(out),
            "--resume",
        )
        == 0
    )
    assert "2 recordings collected now, 4 already there; 6 in the file" in capsys.readouterr().out
    # Each trial is simulated from its own seed: a file made in one go holds the same data.
    whole = workdir / "b.h5"
    assert (
        collect(
            workdir, "--objects", "towel,cork_board", "--actions", "Pq", "-n", "3", "-o", str(whole)
        )
        == 0
    )
    with DatasetReader(out) as a, DatasetReader(whole) as b:
        assert sorted(a.keys()) == sorted(b.keys())
        for i in range(len(b)):
            key = b.key(i)
            raw = a.raw(a.keys().index(key))
            for name, values in b.raw(i).items():
                np.testing.assert_array_equal(raw[name], values)
            if key in first:
                np.testing.assert_array_equal(first[key]["force"], raw["force"])


def test_collect_refuses_what_would_mix_or_lose_data(workdir: Path, capsys):
    out = workdir / "c.h5"
    assert collect(workdir, "--objects", "towel", "--actions", "Pq", "-n", "1", "-o", str(out)) == 0
    capsys.readouterr()
    assert collect(workdir, "--objects", "towel", "--actions", "Pq", "-n", "1", "-o", str(out)) == 1
    assert "exists: use --resume" in capsys.readouterr().err
    other = workdir / "other_actions.toml"
    other.write_text(ACTIONS_TOML.replace("hold_time = 0.5", "hold_time = 0.7"))
    assert (
        main(
            [
                "collect",
                "--robot",
                "sim",
                "--actions-file",
                str(other),
                "--objects",
                "towel",
                "--actions",
                "Pq",
                "-n",
                "2",
                "-o",
                str(out),
                "--resume",
                "--no-progress",
                "--thermal-wait",
                "0",
            ]
        )
        == 1
    )
    assert "action 'Pq' was recorded with other parameters" in capsys.readouterr().err
    assert (
        collect(
            workdir,
            "--objects",
            "towel",
            "--actions",
            "Pq",
            "-n",
            "2",
            "-o",
            str(out),
            "--resume",
            "--seed",
            "5",
        )
        == 1
    )
    assert "simulated with --seed 0, not 5" in capsys.readouterr().err
    assert (
        collect(
            workdir,
            "--objects",
            "towel,no_such_thing",
            "--actions",
            "Pq",
            "-n",
            "1",
            "-o",
            str(workdir / "d.h5"),
        )
        == 1
    )
    assert "no object(s) no_such_thing" in capsys.readouterr().err
    assert (
        collect(
            workdir,
            "--objects",
            "towel",
            "--actions",
            "Pq",
            "-n",
            "1",
            "-o",
            str(workdir / "d.h5"),
            "--workspace",
            "cell.toml",
        )
        == 1
    )
    assert "only for --robot ur10" in capsys.readouterr().err
    assert not (workdir / "d.h5").exists()
    with DatasetReader(out) as rd:
        assert len(rd) == 1


def test_learn_prints_its_own_estimate_and_stops_at_the_target_accuracy(
    workdir: Path, prior: Path, capsys
):
    """Without a test set the learner's own estimate is all there is; with --target-accuracy
    the run stops on the first step whose estimate reaches it, and says so."""
    out = workdir / "target"
    argv = ("--objects", NEW, "--budget", "8", "--seed", "1", "--target-accuracy", "0.01")
    assert learn(workdir, prior, out, *argv) == 0
    text = capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    estimates = [s["estimated_accuracy"] for s in run["steps"]]
    # The estimate exists once every action has a judged touch; 0.01 is reached there.
    assert estimates[0] is None and estimates[-1] is not None
    assert all(e is None for e in estimates[:-1]) and len(estimates) <= 9
    assert f"estimated accuracy {estimates[-1]:.3f} (its own, no test data)" in text
    assert run["stop_reason"] == "target accuracy"
    assert f"completed (stopped early: target accuracy): {len(estimates)} steps" in text


def test_learn_without_a_test_set_reports_choices_and_transfer_but_no_accuracy(
    workdir: Path, prior: Path, capsys
):
    out = workdir / "run1"
    assert learn(workdir, prior, out, "--objects", NEW, "--budget", "3", "--seed", "1") == 0
    text = capsys.readouterr().out
    assert "no test set: accuracy is not reported" in text
    assert "exploring smooth_sponge with Pq (trial 0)" in text
    assert "step   0: initial round done (4 observations" in text
    assert "transfer Pq: smooth_sponge" in text and "step   3/3:" in text
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "completed" and run["accuracy_reported"] is False
    assert [s["step"] for s in run["steps"]] == [0, 1, 2, 3]
    assert all(s["mean_accuracy"] is None for s in run["steps"])
    assert (
        run["config"]["budget"] == 3
        and run["config"]["transfer"] == "paper"
        and run["config"]["seed"] == 1
    )
    # The decisions follow Eq. 3 and the evidence cut-off: a source only when its mean
    # posterior reaches eps_neg and the new labels' log Bayes factor exceeds the margin.
    margin = run["config"]["evidence_margin"]
    for step in run["steps"]:
        for decisions in step["transfer"].values():
            for d in decisions.values():
                best = max(d["mean_posterior"], key=d["mean_posterior"].get)
                passes = d["mean_posterior"][best] >= run["config"]["eps_neg"]
                tested = d["log_bayes_factor"]
                assert set(tested) == ({best} if passes else set())
                if passes and tested[best] > margin:
                    assert d["source"] == best and d["lambda"] == d["mean_posterior"][best]
                else:
                    assert d["source"] is None and d["lambda"] == 0.0
    with open(out / "steps.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["action"] for r in rows[1:]] == [s["action"] for s in run["steps"][1:]]
    with open(out / "transfer.csv") as fh:
        assert (
            len(list(csv.DictReader(fh))) == 2 * 2 + 3 * 2
        )  # step 0: both actions; then the updated one
    # Every observation is a stored recording; what was learned can become prior knowledge.
    with DatasetReader(out / "recordings.h5") as rd:
        assert len(rd) == 4 + 3
        assert {rd.key(i)[0] for i in range(len(rd))} == set(NEW.split(","))
    learned = PriorKnowledge.load(out / "learned_prior.npz")
    assert learned.objects == sorted(NEW.split(",")) and set(learned.actions) == {"Pq", "Sq"}
    counts = run["observations"]
    for action, ap in learned.actions.items():
        for obj in NEW.split(","):
            assert int(np.sum(ap.observations.objects == obj)) == counts[action][obj]
    # ... for instance as the prior of the next objects.
    assert (
        learn(
            workdir,
            out / "learned_prior.npz",
            workdir / "run2",
            "--objects",
            "towel,cork_board",
            "--budget",
            "1",
            "--actions",
            "Pq",
        )
        == 0
    )


def test_learn_with_a_test_set_reports_accuracy(workdir: Path, prior: Path, capsys):
    test = workdir / "test.h5"
    assert (
        collect(
            workdir,
            "--objects",
            NEW,
            "--actions",
            "Pq",
            "-n",
            "3",
            "--first-trial",
            "100",
            "-o",
            str(test),
        )
        == 0
    )
    out = workdir / "run3"
    record = workdir / "shared_record.h5"
    assert (
        learn(
            workdir,
            prior,
            out,
            "--objects",
            NEW,
            "--actions",
            "Pq",
            "--budget",
            "2",
            "--test",
            str(test),
            "--record",
            str(record),
            "--transfer",
            "none",
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "no test set" not in text and "test accuracy" in text and "transfer Pq" not in text
    run = json.loads((out / "run.json").read_text())
    assert run["accuracy_reported"] is True and run["test"]["path"] == str(test)
    accuracies = [s["mean_accuracy"] for s in run["steps"]]
    assert all(0.0 <= a <= 1.0 for a in accuracies)
    assert all(d == {} for s in run["steps"] for d in s["transfer"].values())
    # A second run appends to the same record file; its trial numbers continue.
    with DatasetReader(record) as rd:
        before = rd.keys()
    assert len(before) == 2 + 2
    assert (
        learn(
            workdir,
            prior,
            workdir / "run4",
            "--objects",
            NEW,
            "--actions",
            "Pq",
            "--budget",
            "0",
            "--record",
            str(record),
        )
        == 0
    )
    first = max(t for _, _, t in before) + 1
    assert json.loads((workdir / "run4" / "run.json").read_text())["first_trial"] == first
    with DatasetReader(record) as rd:
        assert sorted(rd.keys()) == sorted(before + [(o, "Pq", first) for o in NEW.split(",")])


def test_learn_rejects_inconsistent_objects_and_actions(workdir: Path, prior: Path, capsys):
    assert learn(workdir, prior, workdir / "bad", "--objects", "rough_sponge,hard_box") == 1
    assert "already in the prior knowledge" in capsys.readouterr().err
    assert learn(workdir, prior, workdir / "bad", "--objects", NEW, "--actions", "P1") == 1
    assert "no experience of P1" in capsys.readouterr().err
    assert learn(workdir, prior, workdir / "bad", "--objects", "hard_box") == 1
    assert "at least two new objects" in capsys.readouterr().err
    assert learn(workdir, workdir / "missing.npz", workdir / "bad", "--objects", NEW) == 1
    assert "no such file" in capsys.readouterr().err
    assert not (workdir / "bad").exists()


def test_prompt_between_trials_waits_for_the_operator(workdir: Path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n\n"))
    out = workdir / "prompted.h5"
    assert (
        collect(
            workdir,
            "--objects",
            "towel",
            "--actions",
            "Pq",
            "-n",
            "3",
            "-o",
            str(out),
            "--prompt-between-trials",
        )
        == 0
    )
    err = capsys.readouterr().err
    assert err.count("re-place the objects") == 2 and "Trial 1:" in err and "Trial 2:" in err
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))  # the operator is gone: stop, keep the data
    out = workdir / "prompted2.h5"
    assert (
        collect(
            workdir,
            "--objects",
            "towel",
            "--actions",
            "Pq",
            "-n",
            "3",
            "-o",
            str(out),
            "--prompt-between-trials",
        )
        == 1
    )
    with DatasetReader(out) as rd:
        assert rd.keys() == [("towel", "Pq", 0)]


class FaultySession(SimSession):
    """The simulated world, with a protective stop in the middle of the ``fail_at``-th action
    (what was recorded so far travels with the error, as from the UR10)."""

    def __init__(self, fail_at: int):
        super().__init__(seed=0)
        self.calls, self.fail_at = 0, fail_at

    def explore(self, obj, action, trial):
        rec = super().explore(obj, action, trial)
        self.calls += 1
        if self.calls < self.fail_at:
            return rec
        rec.metadata["aborted"] = "ProtectiveStopError: injected"
        err = ProtectiveStopError("injected")
        raise TrialFault(err, rec) from err


def test_a_fault_during_live_learning_keeps_every_observation_and_the_run_so_far(
    workdir: Path, prior: Path
):
    actions = actions_from_toml(workdir / "actions.toml")
    out, record = workdir / "faulty", workdir / "faulty" / "rec.h5"
    lines: list[str] = []
    with pytest.raises(LiveLearningAborted) as err:
        learn_live(
            FaultySession(fail_at=6),
            PriorKnowledge.load(prior),
            LearnerConfig(budget=5),
            actions,
            NEW.split(","),
            record=record,
            output=out,
            report=lines.append,
        )
    assert "trial" in str(err.value) and isinstance(err.value.cause, ProtectiveStopError)
    run = json.loads((out / "run.json").read_text())
    assert run["status"].startswith("aborted: ProtectiveStopError")
    assert [s["step"] for s in run["steps"]] == [
        0,
        1,
    ]  # 4 initial observations, then step 1; 6th failed
    assert run["fault"]["recording_saved_to"] == str(err.value.saved)
    with DatasetReader(record) as rd:
        assert len(rd) == 5
    with DatasetReader(err.value.saved) as rd:
        assert len(rd) == 1 and "ProtectiveStopError" in rd.recording(0).metadata["aborted"]
    assert PriorKnowledge.load(out / "learned_prior.npz").objects == sorted(NEW.split(","))


@pytest.mark.parametrize("transfer", ["control", "none"])
def test_learn_takes_every_transfer_mode(workdir: Path, prior: Path, transfer: str, capsys):
    out = workdir / f"run-{transfer}"
    assert (
        learn(workdir, prior, out, "--objects", NEW, "--budget", "1", "--transfer", transfer) == 0
    )
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "completed" and run["config"]["transfer"] == transfer
    decided = [d for s in run["steps"] for ds in s["transfer"].values() for d in ds.values()]
    if transfer == "multi":
        assert decided  # one decision per action and new object at step 0, then per update
        # Every source above the cut-off, each with its own λ = its p̄.
        for d in decided:
            assert d["sources"] == {
                o: p for o, p in d["mean_posterior"].items() if p >= run["config"]["eps_neg"]
            }
    else:
        assert not decided  # the baseline and the control make no transfer decisions


def test_learn_says_what_each_new_object_learned_from_or_why_not(
    workdir: Path, prior: Path, capsys
):
    """Each step's decisions, and at the end the ones in force, name the prior object learned
    from with λ or the rule that stopped the transfer: eps_neg, or the same-object cut-off with
    the threshold it had to beat."""
    out = workdir / "run-words"
    assert learn(workdir, prior, out, "--objects", NEW, "--budget", "2", "--seed", "3") == 0
    text = capsys.readouterr().out
    run = json.loads((out / "run.json").read_text())
    margin, eps_neg = run["config"]["evidence_margin"], run["config"]["eps_neg"]
    step_lines = [ln for ln in text.splitlines() if ln.startswith("    transfer ")]
    decided = [d for s in run["steps"] for ds in s["transfer"].values() for d in ds.values()]
    assert len(step_lines) == sum(len(s["transfer"]) for s in run["steps"])
    words = "\n".join(step_lines)
    sources = [d for d in decided if d["source"]]
    stopped = [d for d in decided if not d["source"] and d["log_bayes_factor"]]
    below = [d for d in decided if not d["source"] and not d["log_bayes_factor"]]
    assert words.count(" <- ") == len(sources)
    assert words.count("(same-object cut-off)") == len(stopped)
    assert words.count(f"< eps_neg {eps_neg:g})") == len(below)
    for d in stopped:  # the look-alike and its log odds, as the learner judged them
        ((old, log_odds),) = d["log_bayes_factor"].items()
        assert d["threshold"] >= margin
        assert f"{d['new_object']}: no transfer, most like {old}" in words
        assert f"log odds {log_odds:.1f} <= {d['threshold']:.3g}" in words
    # The decisions in force at the end: the last one of each action and new object.
    final: dict[tuple[str, str], dict] = {}
    for step in run["steps"]:
        for action, ds in step["transfer"].items():
            final.update({(action, obj): d for obj, d in ds.items()})
    tail = text[text.index("transfer at the end") :].splitlines()[1 : 1 + len(final)]
    assert len(tail) == len(final) == 2 * len(NEW.split(","))
    told: dict[tuple[str, str], str] = {}
    action = ""
    for line in tail:
        body = line[2:]
        if not body.startswith(" "):  # the action is named on its first line
            action, body = body.split(maxsplit=1)
        told[(action, body.split()[0].rstrip(":"))] = body.strip()
    assert set(told) == set(final)
    for (action, obj), d in final.items():
        if d["source"]:
            assert told[action, obj].startswith(f"{obj} <- {d['source']} (lambda {d['lambda']:.2f}")
        else:
            assert told[action, obj].startswith(f"{obj}: no transfer, most like ")


def test_learn_can_start_from_recognition_and_grow_the_library(workdir: Path, prior: Path, capsys):
    """--recognise: each candidate is touched once with every action and recognised; the known
    ones are reported and left alone, the new ones learned (their touches are the first round:
    never repeated) and, with --merge-into, added to the library."""
    out = workdir / "recognise"
    grown = workdir / "grown.npz"
    candidates = "rough_sponge,metal_toolbox,smooth_sponge,hard_box"
    argv = ["--objects", candidates, "--actions", "Pq,Sq", "--budget", "2", "--recognise"]
    assert learn(workdir, prior, out, *argv, "--merge-into", str(grown)) == 0
    said = capsys.readouterr().out
    assert "recognised: rough_sponge is rough_sponge" in said
    assert "recognised: metal_toolbox is metal_toolbox" in said
    assert "recognised: smooth_sponge is new" in said and "recognised: hard_box is new" in said
    run = json.loads((out / "run.json").read_text())
    assert run["new_objects"] == ["smooth_sponge", "hard_box"]
    assert len(run["recognition"]) == 4
    # The recognition touches are the learner's first round: 4 objects × 2 actions, then the
    # budget — nothing repeated.
    with DatasetReader(out / "recordings.h5") as rd:
        assert len(rd) == 4 * 2 + 2
    library = PriorKnowledge.load(grown)
    assert set(library.objects) == set(PRIORS.split(",")) | {"smooth_sponge", "hard_box"}
    assert [p["source"] for p in library.metadata["provenance"]] == [
        str(prior),
        str(out / "learned_prior.npz"),
    ]
    # --recognise and --merge-into are for live runs only.
    assert main(["learn", "--table", "x.csv", "--recognise", "--objects", "a,b"]) == 1
    assert "--recognise: only for a live run" in capsys.readouterr().err


def test_a_live_run_replaces_links_in_its_output_and_keeps_their_targets(
    workdir: Path, prior: Path, tmp_path: Path, capsys
):
    """run.json, steps.csv, transfer.csv and learned_prior.npz planted as links to files
    elsewhere: with --force the run replaces the links, and the files they point at keep every
    byte."""
    out, outside = tmp_path / "out", tmp_path / "outside"
    out.mkdir()
    outside.mkdir()
    names = ("run.json", "steps.csv", "transfer.csv", "learned_prior.npz")
    for name in names:
        (outside / name).write_text("precious")
        (out / name).symlink_to(outside / name)
    argv = ["--objects", NEW, "--actions", "Pq", "--budget", "1"]
    assert learn(workdir, prior, out, *argv) == 1
    assert "holds an earlier result" in capsys.readouterr().err
    assert learn(workdir, prior, out, *argv, "--force") == 0
    for name in names:
        assert (outside / name).read_text() == "precious", name
        assert (out / name).is_file() and not (out / name).is_symlink(), name
    # The run's own learned objects are not a library to merge into.
    capsys.readouterr()
    own = ["--merge-into", str(out / "learned_prior.npz"), "--force"]
    assert learn(workdir, prior, out, *argv, *own) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is the run's own learned_prior.npz" in err[0], err


@pytest.mark.parametrize(
    "when, phase",
    [
        ("recognised:", "the recognition touches"),
        ("step   1", "learning after step 1"),
    ],
    ids=["recognising", "updating"],
)
def test_ctrl_c_between_trials_writes_the_run_so_far_and_names_where(
    workdir: Path, prior: Path, tmp_path: Path, when: str, phase: str
):
    """Ctrl-C while no trial is under way (the library recognising the touched objects, the
    models updating): every recording is kept, run.json says where the run stopped, and the
    interruption's note names the last trial."""
    actions = actions_from_toml(workdir / "actions.toml")
    out, record = tmp_path / "out", tmp_path / "out" / "rec.h5"
    recognising = when == "recognised:"
    # Recognition's candidates include a known object; learning's are new ones only.
    objects = ["rough_sponge", *NEW.split(",")] if recognising else NEW.split(",")

    def report(line: str) -> None:
        if when in line:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as err:
        learn_live(
            SimSession(),
            PriorKnowledge.load(prior),
            LearnerConfig(budget=3),
            actions,
            objects,
            record=record,
            output=out,
            report=report,
            recognise_first=recognising,
        )
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["interrupted"]["during"] == phase
    assert "/ trial " in run["interrupted"]["after"]
    if sys.version_info >= (3, 11):
        note = " ".join(err.value.__notes__)
        assert f"interrupted at {phase}, after " in note and str(record) in note
    with DatasetReader(record) as rd:
        assert len(rd) >= 3
