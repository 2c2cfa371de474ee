"""Feature tables (``aptkt learn --table``): reading and writing CSV and HDF5, every validation
error as one line naming the row or column, and the offline comparison end to end."""

from __future__ import annotations

import csv
import json

import h5py
import numpy as np
import pytest

from aptkt.cli import main
from aptkt.errors import FeatureTableError
from aptkt.learning import GPSettings, LearnerConfig, Observations, PriorKnowledge
from aptkt.learning.feature_table import (
    read_feature_table,
    split_held_out,
    write_feature_table,
)

from .synthetic import draw, make_world

PRIORS, NEW = ["old0", "old1", "old2"], ["new0", "new1", "new2"]


def _world_table(n_per=6):
    """Two actions with different modalities (thermal 6-d on both, force on P1, texture on S1)."""
    priors, news, means = make_world(n_prior=3, n_new=3, related=True, seed=1)
    table = draw(means, priors + news, n_per, seed=2)
    for obs in table.values():
        obs.trials = np.tile(np.arange(n_per), len(priors + news))
    return table


def _equal(a: dict[str, Observations], b: dict[str, Observations]) -> None:
    assert list(a) == list(b)
    for name in a:
        # Modalities come in the table's column order, whatever order they were given in.
        assert sorted(a[name].modality_names) == sorted(b[name].modality_names)
        for m in a[name].modality_names:
            np.testing.assert_array_equal(a[name].modalities[m], b[name].modalities[m])
        np.testing.assert_array_equal(a[name].objects, b[name].objects)
        np.testing.assert_array_equal(a[name].trials, b[name].trials)


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_round_trip_is_exact(tmp_path, suffix):
    table = _world_table()
    path = write_feature_table(tmp_path / f"t{suffix}", table)
    read = read_feature_table(path)
    assert read.action_names == ["P1", "S1"]
    assert read.columns[:2] == ["force.0", "thermal.0"]
    _equal(read.observations(), table)


def test_held_out_split_by_trial(tmp_path):
    read = read_feature_table(write_feature_table(tmp_path / "t.csv", _world_table()))
    pool, test = split_held_out(read, ["P1", "S1"], NEW)
    assert set(read.trials[pool]) == {0, 1, 2} and set(read.trials[test]) == {3, 4, 5}
    assert set(read.objects[pool | test]) == set(NEW)
    pool, test = split_held_out(read, ["P1"], NEW, test_trials=[0, 5])
    assert set(read.trials[test]) == {0, 5} and set(read.trials[pool]) == {1, 2, 3, 4}
    with pytest.raises(FeatureTableError, match="no row left to learn from"):
        split_held_out(read, ["P1"], NEW, test_trials=range(6))


def _write_csv(path, header, rows):
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return path


GOOD_HEADER = ["object", "action", "trial", "force.0", "thermal.0", "thermal.1"]


def _good_rows():
    rows = []
    for o, obj in enumerate(["a", "b", "c", "d"]):
        for t in range(3):
            rows.append([obj, "P1", t, o + 0.1 * t, o, -o])
    return rows


def _learn(path, capsys, *extra):
    code = main(
        ["learn", "--table", str(path), "--prior-objects", "a,b", "--objects", "c,d"]
        + ["--budget", "1", "--runs", "1", "-o", str(path.parent / "out"), *extra]
    )
    err = capsys.readouterr().err.strip()
    return code, err


def _bad(tmp_path, edit):
    header, rows = list(GOOD_HEADER), _good_rows()
    header, rows = edit(header, rows) or (header, rows)
    return _write_csv(tmp_path / "t.csv", header, rows)


@pytest.mark.parametrize(
    "edit,message",
    [
        (
            lambda h, r: (h[:1] + h[2:], [x[:1] + x[2:] for x in r]),
            "missing column(s) action",
        ),
        (lambda h, r: (h[:-1] + ["thermal_1"], r), "column 'thermal_1': is neither"),
        (lambda h, r: (h[:-1] + ["thermal.2"], r), "modality thermal has no column thermal.1"),
        (lambda h, r: r[4].__setitem__(3, "inf"), "row 5, column force.0: non-finite value 'inf'"),
        (lambda h, r: r[6].__setitem__(5, "nan"), "row 7, column thermal.1: non-finite value"),
        (lambda h, r: r[2].__setitem__(4, "1,5"), "row 3, column thermal.0: '1,5' is not a number"),
        (lambda h, r: r[1].__setitem__(2, "x"), "row 2, column trial: 'x' is not a whole"),
        (
            lambda h, r: r[1].__setitem__(2, "100000000000000000000"),
            "row 2, column trial: trial 100000000000000000000 is not within 0..2147483647",
        ),
        (lambda h, r: r[1].__setitem__(2, "-1"), "row 2, column trial: trial -1 is not within"),
        (
            lambda h, r: r[8].__setitem__(4, ""),
            "row 9, column thermal.0: empty, but filled in row 1",
        ),
        (lambda h, r: r[3].__setitem__(0, ""), "row 4, column object: empty name"),
        (
            lambda h, r: r[3].__setitem__(0, "b\x00c"),
            "row 4, column object: a name with the control character '\\x00': 'b\\x00c'",
        ),
        (
            lambda h, r: r[3].__setitem__(0, "b\nc"),
            "row 4, column object: a name with the control character '\\n'",
        ),
        (
            lambda h, r: r[3].__setitem__(1, "P\x1b[2J"),
            "row 4, column action: a name with the control character '\\x1b'",
        ),
        (
            lambda h, r: r[3].__setitem__(0, "x" * 10_000),
            "row 4, column object: a name of 10,000 characters (at most 200)",
        ),
        (
            lambda h, r: r[4].__setitem__(2, "0"),
            "row 5: object b, action P1, trial 0 also in row 4",
        ),
        (lambda h, r: r.append(["e", "P1", 0, 1.0, 2.0]), "row 13: 5 cells, but the header has 6"),
        (
            lambda h, r: (h, [x for x in r if not (x[0] == "d" and x[2] > 0)]),
            "object d has 1 row(s) of action P1 (rows: 10); learning needs at least 2",
        ),
    ],
)
def test_bad_tables_give_one_line_naming_the_place(tmp_path, capsys, edit, message):
    path = _bad(tmp_path, edit)
    code, err = _learn(path, capsys)
    assert code == 1
    assert err.count("\n") == 0, err
    assert err.startswith(f"aptkt learn: error: {path}"), err
    assert message in err, err


def test_hdf5_tables_are_checked_too(tmp_path, capsys):
    path = write_feature_table(tmp_path / "t.h5", _world_table())
    with h5py.File(path, "a") as f:
        f["thermal.2"][7] = np.inf
    code, err = _learn(path, capsys)
    assert code == 1 and "row 8, column thermal.2: non-finite value inf" in err
    with h5py.File(path, "a") as f:
        f["thermal.2"][7] = np.nan  # an empty cell in a row whose action has the column
    code, err = _learn(path, capsys)
    assert code == 1 and "row 8, column thermal.2: empty, but filled in row 1" in err


@pytest.mark.parametrize("kind", ["external", "soft"])
def test_a_column_that_is_a_link_is_one_line(tmp_path, capsys, kind):
    """An HDF5 column may be a link to another file (missing, or anywhere): a table holds its
    own columns, so a link is refused where the table is read, never followed."""
    path = write_feature_table(tmp_path / "t.h5", _world_table())
    with h5py.File(path, "a") as f:
        del f["thermal.2"]
        f["thermal.2"] = (
            h5py.ExternalLink(str(tmp_path / "gone.h5"), "/x")
            if kind == "external"
            else h5py.SoftLink("/thermal.1")
        )
    code, err = _learn(path, capsys)
    assert code == 1 and "\n" not in err and "Traceback" not in err, err
    assert "column thermal.2: is a link; a feature table holds its columns itself" in err


@pytest.mark.parametrize(
    "args,message",
    [
        (["--prior-objects", "a,zz"], "no rows of prior object(s) zz"),
        (["--objects", "c,a"], "a are both prior and new"),
        (["--actions", "P9"], "no rows of action(s) P9"),
        (["--test-trials", "2:1"], "--test-trials 2:1: 2:1 holds no trial"),
        (["--test-trials", "2-1"], "--test-trials 2-1: the range 2-1 runs backwards"),
        (["--transfer", "none"], "--transfer: not with a table"),
        (["--eps-neg", "2"], "eps_neg must lie in [0, 1]"),
        (["--evidence-margin", "nan"], "evidence_margin must be finite"),
    ],
)
def test_bad_options_give_one_line(tmp_path, capsys, args, message):
    path = _write_csv(tmp_path / "t.csv", GOOD_HEADER, _good_rows())
    code, err = _learn(path, capsys, *args)
    assert code == 1 and err.count("\n") == 0 and message in err, err


def test_live_options_are_not_mixed_up(capsys):
    assert main(["learn", "--objects", "a,b", "--prior", "p.npz", "--runs", "2"]) == 1
    err = capsys.readouterr().err
    assert "--robot is required (or learn offline: aptkt learn TABLE ...)" in err


def test_method_choices_reach_every_method_and_the_prior(tmp_path, capsys):
    """--reading paper picks the paper's whole reading; --cutoff and --evidence-margin set
    APTKT's and APTKT+aux's learner, --kernel and --prior-feature-scale the
    GP settings of every model, the prior's too; a mistake is one line."""
    table = _world_table(n_per=4)
    path = write_feature_table(tmp_path / "t.csv", table)
    out = tmp_path / "out"
    args = ["learn", "--table", str(path), "--prior-objects", ",".join(PRIORS)]
    args += ["--objects", ",".join(NEW), "--budget", "1", "--runs", "1", "-o", str(out)]
    with pytest.raises(SystemExit) as usage:  # argparse's usage error: a number is needed
        main([*args, "--evidence-margin", "lnN"])
    assert usage.value.code == 2 and "--evidence-margin" in capsys.readouterr().err
    assert main([*args, "--reading", "paper", "--evidence-margin", "1.5"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    aptkt = LearnerConfig.from_dict(summary["learner"]["APTKT"])
    assert aptkt == LearnerConfig.paper(
        budget=1, seed=0, evidence_margin=1.5, eps_neg=aptkt.eps_neg, eps_explor=aptkt.eps_explor
    )
    baseline = LearnerConfig.from_dict(summary["learner"]["baseline"])
    assert baseline.transfer == "none" and baseline.gp == GPSettings.paper()
    prior = PriorKnowledge.load(out / "prior.npz")
    assert prior.feature_scale == "spread"
    assert {prior[a].model.kernel for a in prior.actions} == {"per-classifier"}
    out2 = tmp_path / "out2"
    args2 = [a if a != str(out) else str(out2) for a in args]
    args2 += ["--kernel", "per-classifier", "--prior-feature-scale", "spread"]
    assert main(args2) == 0, capsys.readouterr().err
    summary = json.loads((out2 / "summary.json").read_text())
    gp = LearnerConfig.from_dict(summary["learner"]["APTKT+aux"]).gp
    assert gp == GPSettings(kernel="per-classifier", prior_feature_scale="spread")
    assert PriorKnowledge.load(out2 / "prior.npz").feature_scale == "spread"


@pytest.mark.slow
def test_learn_from_a_table_writes_the_demo_outputs(tmp_path, capsys):
    """CSV and HDF5 give the same results; every method learns from the related priors."""
    table = _world_table(n_per=8)
    results = {}
    for suffix in (".csv", ".h5"):
        path = write_feature_table(tmp_path / f"t{suffix}", table)
        out = tmp_path / f"out{suffix}"
        args = ["learn", "--table", str(path), "--prior-objects", ",".join(PRIORS)]
        args += ["--objects", ",".join(NEW), "--budget", "3", "--runs", "2", "-o", str(out)]
        assert main(args) == 0
        printed = capsys.readouterr().out
        assert "APTKT+aux" in printed and "baseline" in printed
        for name in (
            "results.csv",
            "learning_curves.png",
            "confusion.csv",
            "confusion.png",
            "prior.npz",
        ):
            assert (out / name).is_file(), name
        summary = json.loads((out / "summary.json").read_text())
        with (out / "results.csv").open() as fh:
            rows = list(csv.DictReader(fh))
        assert {r["method"] for r in rows} == {"APTKT", "APTKT+aux", "baseline"}
        assert len(rows) == 3 * 2 * (3 + 1)
        results[suffix] = [(r["method"], r["run"], r["step"], r["mean_accuracy"]) for r in rows]
        assert set(summary["final_mean_accuracy"]) == {"APTKT", "APTKT+aux", "baseline"}
        for acc in summary["final_mean_accuracy"].values():
            assert 0.5 < acc <= 1.0  # 3 well separated new objects: far above chance (1/3)
        assert summary["settings"]["prior_objects"] == PRIORS
    assert results[".csv"] == results[".h5"]


def test_learning_from_a_table_says_what_each_new_object_learned_from(tmp_path, capsys):
    """The printed summary, report.md and summary.json name, per action and new object, the
    prior object each run's final model learned from — the one whose λ the model carries."""
    path = write_feature_table(tmp_path / "t.csv", _world_table(n_per=4))
    out = tmp_path / "out"
    args = ["learn", "--table", str(path), "--prior-objects", ",".join(PRIORS), "--objects"]
    args += [",".join(NEW), "--budget", "1", "--runs", "2", "--cutoff", "paper", "-o", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    lines = summary["transfer"]["APTKT"]
    assert len(lines) == 2 * len(NEW)  # two actions
    for line in lines:
        assert "        " + line in printed.splitlines()
    assert set(summary["transfer"]) == {"APTKT", "APTKT+aux"}
    report = (out / "report.md").read_text()
    assert all(line in report for line in lines) and "transfer_APTKT.png" in report
    assert (out / "transfer_APTKT.png").stat().st_size > 0
    # What each run's final APTKT model carries: a λ column of exactly one prior object.
    with (out / "results.csv").open() as fh:
        rows = [r for r in csv.DictReader(fh) if r["method"] == "APTKT"]
    last = [max((r for r in rows if r["run"] == t), key=lambda r: int(r["step"])) for t in "01"]
    told, action = {}, ""
    for line in lines:
        if not line.startswith(" "):
            action, line = line.split(maxsplit=1)
        told[action, line.split()[0].rstrip(":")] = line.strip()
    assert any(" <- " in text for text in told.values())  # related priors: Eq. 3 transfers
    for (action, obj), text in told.items():
        carried = {
            k.split(".lambda[")[1][:-1]
            for r in last
            for k, v in r.items()
            if k.startswith(f"hp[{action}][{obj}].lambda[") and v not in ("", None)
        }
        if carried:
            (source,) = carried
            assert text.startswith(f"{obj} <- {source} (lambda ") and text.endswith("2/2 runs")
        else:
            assert text.startswith(f"{obj}: no transfer")


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_the_extraction_column_round_trips_and_is_not_a_feature(tmp_path, suffix):
    path = write_feature_table(tmp_path / f"t{suffix}", _world_table(), extraction="aptkt-skin")
    read = read_feature_table(path)
    assert read.extraction == "aptkt-skin"
    assert "extraction" not in read.columns
    _equal(read.observations(), _world_table())
    assert (
        read_feature_table(write_feature_table(tmp_path / f"u{suffix}", _world_table())).extraction
        is None
    )


@pytest.mark.parametrize(
    "cell, message",
    [
        ("", "row 3, column extraction: empty name"),
        ("biotac", "row 3, column extraction: 'biotac', but 'aptkt-skin' in row 1"),
    ],
)
def test_one_extraction_per_table(tmp_path, capsys, cell, message):
    rows = [[*r[:3], "aptkt-skin", *r[3:]] for r in _good_rows()]
    rows[2][3] = cell
    path = _write_csv(tmp_path / "t.csv", [*GOOD_HEADER[:3], "extraction", *GOOD_HEADER[3:]], rows)
    code, err = _learn(path, capsys)
    assert code == 1 and err == f"aptkt learn: error: {path}, {message}" + (
        ": features computed in different ways cannot be learnt from together" if cell else ""
    )


def test_the_transforms_follow_the_extraction_not_the_modality_names():
    from aptkt.errors import ConfigError
    from aptkt.learning.pipeline import GENERIC_TRANSFORMS, SKIN_TRANSFORMS, transforms_of

    assert transforms_of(None) is GENERIC_TRANSFORMS
    assert transforms_of("biotac") is GENERIC_TRANSFORMS
    assert transforms_of("aptkt-skin") is SKIN_TRANSFORMS
    assert transforms_of(None, "aptkt-skin") is SKIN_TRANSFORMS
    assert transforms_of("aptkt-skin", "other") is GENERIC_TRANSFORMS
    with pytest.raises(ConfigError, match="extraction must be one of"):
        transforms_of(None, "skin")


@pytest.mark.parametrize(
    ("given", "reading", "gate"),
    [
        ([], "aptkt", 3.0),
        ([], "paper", None),
        (["--aux-gate-margin", "5"], "aptkt", 5.0),
        (["--aux-gate-margin", "none"], "aptkt", None),
        (["--aux-gate-margin", "2.5"], "paper", 2.5),
    ],
)
def test_the_auxiliary_gate_has_its_own_option(given, reading, gate):
    """--aux-gate-margin sets LearnerConfig.aux_gate_margin, independent of --evidence-margin."""
    from aptkt.cli import build_parser
    from aptkt.commands._method import learner_config

    for command in (["learn", "--table", "t.csv", "--objects", "a,b"], ["benchmark", "t.csv"]):
        args = build_parser().parse_args([*command, "--reading", reading, *given])
        config = learner_config(args)
        assert config.aux_gate_margin == gate
        assert config.evidence_margin == LearnerConfig.evidence_margin


def test_an_auxiliary_gate_that_is_no_number_is_one_usage_line(capsys):
    with pytest.raises(SystemExit) as usage:
        main(["learn", "--table", "t.csv", "--aux-gate-margin", "strong"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert usage.value.code == 2
    assert err == (
        "aptkt learn: error: argument --aux-gate-margin: a number (a log Bayes factor) or none, "
        "got 'strong'"
    )


@pytest.mark.parametrize("seed", range(12))
def test_random_bytes_named_csv_are_one_line_everywhere(tmp_path, capsys, seed):
    """4,000 random bytes (stray carriage returns, NULs, bytes that are no UTF-8) named .csv."""
    path = tmp_path / "noise.csv"
    path.write_bytes(np.random.default_rng(seed).bytes(4000))
    for argv in (
        ["prior", "build", str(path), "-o", str(tmp_path / "p.npz")],
        ["learn", "--table", str(path), "--prior-objects", "a,b", "--objects", "c,d"],
        ["benchmark", str(path), "-o", str(tmp_path / "b")],
    ):
        assert main(argv) == 1, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(path) in err[0], (argv, err)


def test_the_table_is_given_as_learns_input_and_trials_choose_its_rows(tmp_path, capsys):
    """TABLE is the table mode (--table, the earlier spelling, alike); --trials keeps the rows of
    those trials before the new objects' rows are split, and summary.json records them."""
    path = _write_csv(tmp_path / "t.csv", GOOD_HEADER, _good_rows())
    common = ["--prior-objects", "a,b", "--objects", "c,d", "--budget", "1", "--runs", "1"]
    out = tmp_path / "positional"
    assert main(["learn", str(path), *common, "--trials", "0-1", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"{path}: 8 rows" in said and "2 rows to learn from and 2 held out" in said, said
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["trials"] == "0-1"
    code, err = _learn(path, capsys, "--trials", "1-5")
    assert code == 1 and err == (
        f"aptkt learn: error: --trials 1-5: trial(s) 3-5 not in {path} (it has trials 0-2)"
    )
    code, err = _learn(path, capsys, "--trials", "0,2", "--test-trials", "2")
    assert code == 0, err


def test_a_table_that_never_varies_within_an_object_is_one_line_without_warnings(tmp_path, capsys):
    """Every repeat of every touch reading the same: the library has no noise to measure
    nearness by. It said so with three RuntimeWarnings and a self-contradictory internal
    error; now one line, and no warning on the way."""
    import warnings

    lines = ["object,action,trial,force.0,thermal.0"]
    lines += [f"obj{o},P1,{t},{float(o)},2.0" for o in range(6) for t in range(4)]
    table = tmp_path / "const.csv"
    table.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main(["prior", "build", str(table), "-o", str(tmp_path / "c.npz"), "-j", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and "\n" not in err, err
    assert "do not vary within any object" in err
