"""The command line read as a user reads it: every option explained with its true default,
arguments named after what they are, results never replaced without --force, a closed pipe
ending quietly, and the exit codes docs/reliability.md lists."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from aptkt.cli import build_parser, main
from aptkt.commands._checks import RENAMED_OPTIONS

ROOT = Path(__file__).resolve().parents[2]
PYTHON_DIR = ROOT / "python"

#: What a metavar may not be: says nothing of what the argument is.
VAGUE = {"FILE", "DATA", "PATH", "ARG", "VALUE"}
#: Counts and seeds are numbers, spelt alike everywhere.
COUNTS = {"seed", "jobs", "budget", "trials", "runs", "restarts", "groups", "new", "priors"}


def _actions(parser: argparse.ArgumentParser, path: tuple[str, ...] = ("aptkt",)):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from _actions(child, (*path, name))
        elif not isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            yield " ".join(path), action


ACTIONS = list(_actions(build_parser()))


def _name(command: str, action: argparse.Action) -> str:
    return f"{command} {'/'.join(action.option_strings) or action.dest}"


def _renamed(action: argparse.Action) -> bool:
    """An old spelling kept only to be refused (``prior build --trials``, trial numbers, is
    not the demo's old ``--trials``, runs)."""
    return action.help == argparse.SUPPRESS and any(
        o in RENAMED_OPTIONS for o in action.option_strings
    )


def test_every_option_has_help() -> None:
    missing = [
        _name(c, a)
        for c, a in ACTIONS
        if (not a.help or a.help == argparse.SUPPRESS) and not _renamed(a)
    ]
    assert not missing, f"options without help: {missing}"


def test_one_word_per_concept() -> None:
    """Learning runs are --runs, replacing is --force, the prior's metric is
    --prior-feature-scale, and --jobs defaults to every core, in every command."""
    live = {o for _, a in ACTIONS if not _renamed(a) for o in a.option_strings}
    # "--trials" lives on as trial numbers, one syntax wherever observations are read.
    assert not live & (set(RENAMED_OPTIONS) - {"--trials"}), live & set(RENAMED_OPTIONS)
    trials = [a for _, a in ACTIONS if "--trials" in a.option_strings and not _renamed(a)]
    assert len(trials) >= 4 and all(a.metavar == "TRIALS" for a in trials)
    assert set(RENAMED_OPTIONS.values()) <= live
    jobs = {c: a.default for c, a in ACTIONS if "--jobs" in a.option_strings}
    assert len(jobs) >= 5 and set(jobs.values()) == {os.cpu_count() or 1}, jobs


RENAMED_IN = [(c, o) for c, a in ACTIONS if _renamed(a) for o in a.option_strings]


@pytest.mark.parametrize(("command", "old"), RENAMED_IN, ids=[f"{c} {o}" for c, o in RENAMED_IN])
def test_an_old_spelling_is_refused_with_the_new_one(command, old, capsys) -> None:
    argv = [*command.split()[1:], old, "1"]
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert (
        last
        == f"{command}: error: {old} is now {RENAMED_OPTIONS[old]} (the same meaning in every command)"
    )


def test_every_old_spelling_is_still_caught_somewhere() -> None:
    assert {o for _, o in RENAMED_IN} == set(RENAMED_OPTIONS)


def test_stated_defaults_are_the_defaults() -> None:
    """A help text naming a default names the one argparse uses: choices, numbers, paths."""
    wrong = []
    for command, a in ACTIONS:
        if a.default in (None, False, True) or not a.help:
            continue
        text = a.help % {"default": a.default, "prog": "aptkt"}
        said = re.findall(r"default:? ([^\s,;)]+)", text)
        if said and str(a.default) not in said and "cores" not in text:
            wrong.append(f"{_name(command, a)}: help says default {said}, is {a.default!r}")
        if a.choices and "(default)" in text:
            # "name (default)": the default choice is marked in the help.
            marked = re.findall(r"(\S+): [^;]*\(default\)", text)
            if marked and marked[0] != str(a.default):
                wrong.append(f"{_name(command, a)}: marks {marked[0]}, is {a.default!r}")
    assert not wrong, wrong


def test_arguments_are_named_after_what_they_are() -> None:
    bad = []
    for command, a in ACTIONS:
        if a.nargs == 0 or _renamed(a):
            continue  # a flag, or an old spelling that only refuses
        metavar = a.metavar
        if metavar is None and a.choices is not None:
            continue  # argparse shows the choices
        if metavar is None or not isinstance(metavar, str):
            bad.append(f"{_name(command, a)}: no metavar")
        elif metavar != metavar.upper() or metavar in VAGUE:
            bad.append(f"{_name(command, a)}: {metavar}")
        elif a.dest in COUNTS and a.type is int and metavar != "N":
            bad.append(f"{_name(command, a)}: a count, {metavar} instead of N")
    assert not bad, f"arguments without a telling metavar: {bad}"


def test_a_data_set_argument_is_called_dataset_everywhere() -> None:
    """Each kind of file is called the same wherever it is given."""
    kinds = {}
    for command, a in ACTIONS:
        if isinstance(a.metavar, str) and a.help:
            text = a.help.lower()
            if "data set" in text and "hdf5" in text and "table" not in text:
                kinds[_name(command, a)] = a.metavar
    assert kinds and set(kinds.values()) == {"DATASET"}, kinds


def test_the_overview_names_both_ways_of_learning() -> None:
    help_text = build_parser().format_help()
    line = " ".join(help_text.split("learn", 2)[2].split("reproduce")[0].split())
    assert "--table" in line and "live" in line, line


def _table(tmp_path: Path) -> Path:
    """Two old and two new objects, each new one near an old one; four presses each."""
    centre = {"old0": 0.0, "old1": 3.0, "new0": 0.4, "new1": 3.4}
    lines = ["object,action,trial,force.0,force.1"]
    for k, (obj, c) in enumerate(centre.items()):
        for t in range(4):
            lines.append(f"{obj},P1,{t},{c + 0.1 * t - 0.15},{c - 0.05 * k * t}")
    path = tmp_path / "t.csv"
    path.write_text("\n".join(lines) + "\n")
    return path


def _learn_table(path: Path, out: Path, *extra: str) -> list[str]:
    return ["learn", "--table", str(path), "--prior-objects", "old0,old1"] + [
        "--objects",
        "new0,new1",
        "--budget",
        "1",
        "--runs",
        "1",
        "-o",
        str(out),
        *extra,
    ]


def test_learn_table_does_not_replace_a_result_without_force(tmp_path, capsys) -> None:
    path, out = _table(tmp_path), tmp_path / "out"
    assert main(_learn_table(path, out)) == 0
    (out / "results.csv").write_text("mine")
    capsys.readouterr()
    assert main(_learn_table(path, out)) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds an earlier result" in err[0] and "--force" in err[0], err
    assert (out / "results.csv").read_text() == "mine"
    assert main(_learn_table(path, out, "--force")) == 0
    assert (out / "results.csv").read_text().startswith("method,")


def test_live_learn_does_not_replace_a_run_without_force(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text("{}")
    code = main(
        ["learn", "--robot", "sim", "--prior", str(tmp_path / "none.npz")]
        + [
            "--objects",
            "a,b",
            "-o",
            str(out),
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and "holds an earlier result (run.json)" in err[0], err


def _env() -> dict[str, str]:
    return {
        **os.environ,
        "PYTHONPATH": f"{PYTHON_DIR}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    }


def test_a_closed_pipe_ends_quietly_and_keeps_the_results(tmp_path) -> None:
    """`aptkt learn --table ... | head -1`: the reader leaves after one line; the run goes on,
    writes its results, says nothing on stderr and exits 141 (128 + SIGPIPE)."""
    path, out = _table(tmp_path), tmp_path / "out"
    cmd = [sys.executable, "-m", "aptkt.cli", *_learn_table(path, out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env())
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # as `head -1` does
    err = proc.stderr.read().decode()
    code = proc.wait(timeout=300)
    assert first.startswith(b"[1/3]")
    assert err == "", err
    assert code == 141
    assert (out / "summary.json").is_file() and (out / "results.csv").is_file()


def _exit_code_table() -> dict[int, str]:
    text = (ROOT / "docs" / "reliability.md").read_text(encoding="utf-8")
    section = text.split("### Exit codes", 1)[1].split("\n#", 1)[0]
    return {int(m[0]): m[1] for m in re.findall(r"^\| (\d+) \| (.+?) \|", section, re.M)}


def test_the_exit_codes_are_those_documented(tmp_path, capsys) -> None:
    from aptkt.commands._session import EXIT_FAULT

    table = _exit_code_table()
    assert set(table) == {0, 1, 2, EXIT_FAULT, 130, 141, 143}, table
    # 2: a usage error (a missing required option): the usage, then one error line.
    with pytest.raises(SystemExit) as stop:
        main(["learn", "--robot", "sim"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("usage: aptkt learn")
    assert err[-1] == "aptkt learn: error: the following arguments are required: --objects"
    # 1: a value aptkt's own checks refuse: one line, no usage.
    assert main(["learn", "--robot", "sim", "--objects", "a,b", "--prior", "no.npz"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["aptkt learn: error: --prior no.npz: no such file"], err


def test_prior_build_and_export_do_not_replace_a_file_without_force(tmp_path, capsys) -> None:
    from aptkt.actions import PAPER_ACTIONS
    from aptkt.runtime.generation import GenerationPlan, generate

    data = tmp_path / "d.h5"
    plan = GenerationPlan(("rough_sponge", "towel"), (PAPER_ACTIONS["P1"],), 3, seed=1)
    generate(data, plan, progress=False)
    for command in (
        ["prior", "build", str(data), "-o", str(tmp_path / "p.npz")],
        ["dataset", "export-features", str(data), "-o", str(tmp_path / "t.csv"), "--no-progress"],
    ):
        out = Path(command[command.index("-o") + 1])
        out.write_text("mine")
        assert main(command) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "exists (give --force to replace it)" in err[0], err
        assert out.read_text() == "mine"
        assert main([*command, "--force"]) == 0
        assert out.read_bytes() != b"mine"


def test_method_choices_state_the_defaults_each_reading_uses() -> None:
    """--cutoff, --kernel, --prior-feature-scale: left out, the reading sets them, and their
    help says to what."""
    from aptkt.commands._method import learner_config

    parser = build_parser()
    helps = {
        "/".join(a.option_strings): " ".join(a.help.split())
        for c, a in ACTIONS
        if c == "aptkt learn" and a.help
    }
    for reading in ("aptkt", "paper"):
        args = parser.parse_args(["learn", "--objects", "a,b", "--reading", reading])
        config = learner_config(args)
        for option, used in (
            ("--cutoff", config.cutoff),
            ("--kernel", config.gp.kernel),
            ("--prior-feature-scale", config.gp.prior_feature_scale),
        ):
            said = re.search(
                r"default: ([\w-]+)(?: \(with --reading paper: ([\w-]+)\))?", helps[option]
            )
            assert said, f"{option}: its help states no default: {helps[option]}"
            stated = said[2] if reading == "paper" and said[2] else said[1]
            assert stated == used, f"--reading {reading}: {option} says {stated}, uses {used}"
