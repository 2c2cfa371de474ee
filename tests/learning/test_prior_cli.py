"""`aptkt prior build` and `aptkt prior inspect` on a small simulated data set."""

import json

import numpy as np
import pytest

from aptkt.actions import PAPER_ACTIONS
from aptkt.cli import main
from aptkt.learning import PriorKnowledge
from aptkt.runtime.generation import GenerationPlan, generate


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tmp_path_factory.mktemp("prior") / "d.h5"
    generate(
        path,
        GenerationPlan(("rough_sponge", "metal_toolbox"), (PAPER_ACTIONS["P1"],), 4, seed=3),
        progress=False,
    )
    return path


def test_build_then_inspect(data, tmp_path, capsys):
    out = tmp_path / "prior.npz"
    assert main(["prior", "build", str(data), "-o", str(out), "--trials", "0:3"]) == 0
    prior = PriorKnowledge.load(out)
    assert prior.objects == ["metal_toolbox", "rough_sponge"]
    assert len(prior["P1"].observations) == 6
    capsys.readouterr()
    assert main(["prior", "inspect", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["objects"] == ["metal_toolbox", "rough_sponge"]
    assert summary["actions"][0]["modalities"] == ["force", "thermal"]
    assert np.isclose(sum(summary["actions"][0]["weights_mean"]), 1.0, atol=1e-3)


def test_errors_are_clear(data, tmp_path, capsys):
    assert main(["prior", "build", str(data), "-o", str(tmp_path / "p.npz"), "--trials", "5"]) == 1
    assert "--trials 5: not in" in capsys.readouterr().err
    assert (
        main(["prior", "build", str(data), "-o", str(tmp_path / "p.npz"), "--trials", "3-1"]) == 1
    )
    assert "runs backwards (write 1-3)" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_text("not a prior")
    assert main(["prior", "inspect", str(bad)]) == 1
    assert "not a prior-knowledge file" in capsys.readouterr().err
    assert main(["prior", "build", str(tmp_path / "missing.h5"), "-o", str(bad)]) == 1
    assert "no such data set" in capsys.readouterr().err


@pytest.mark.parametrize("empty", ["no bytes", "no recordings"])
def test_a_data_set_without_recordings_is_one_error_line(data, tmp_path, capsys, empty):
    # The report: `: > e.h5; aptkt prior build e.h5 -o e.npz` ended in a traceback
    # ("ValueError: prior knowledge needs at least one action").
    from aptkt.data import DatasetWriter
    from aptkt.learning.dataset import load_observations

    prior = PriorKnowledge.build(load_observations(data)).save(tmp_path / "p.npz")
    path = tmp_path / "e.h5"
    if empty == "no bytes":
        path.write_bytes(b"")
    else:
        DatasetWriter(path, "w").close()
    commands = {
        "prior build": ["prior", "build", str(path), "-o", str(tmp_path / "e.npz")],
        "export-features": ["dataset", "export-features", str(path), "-o", str(tmp_path / "t.csv")],
        "features": ["dataset", "features", str(path), "--no-progress"],
        "learn --test": [
            "learn",
            "--robot",
            "sim",
            "--prior",
            str(prior),
            "--actions",
            "P1",
            "--test",
            str(path),
            "--objects",
            "towel,cork_board",
            "-o",
            str(tmp_path / "run"),
        ],
        "reproduce --data": [
            "reproduce",
            "fig7",
            "--quick",
            "--data",
            str(path),
            "-o",
            str(tmp_path / "r"),
        ],
    }
    for name, argv in commands.items():
        assert main(argv) == 1, name
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err, (name, err)
        assert f"{path}: holds no recordings" in err, (name, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["e.h5", "p.npz"]


def test_inspect_flags_an_effectively_constant_kernel(tmp_path, capsys):
    """A length-scale far beyond the data's range makes a modality's kernel constant: inspect
    says so, whatever the modality's weight (seen: texture weight 0.36 at length-scale 2.9e4)."""
    from aptkt.learning.observations import Observations

    rng = np.random.default_rng(0)
    objects = np.repeat(["a", "b", "c"], 6)
    force = np.repeat([0.0, 1.0, 2.0], 6)[:, None] + 0.1 * rng.standard_normal((18, 1))
    texture = np.repeat([[0.0, 1, 0], [1, 0, 0], [0, 0, 1]], 6, axis=0) + 0.2 * rng.standard_normal(
        (18, 3)
    )
    table = {"S3": Observations("S3", {"force": force, "texture": texture}, objects)}
    prior = PriorKnowledge.build(table)
    theta = prior["S3"].model.theta_
    theta[:, 1:3] = 0.0  # every length-scale 1: both kernels vary over the data
    out = tmp_path / "p.npz"
    prior.save(out)
    capsys.readouterr()
    assert main(["prior", "inspect", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["actions"][0]["uninformative"] == {}

    k = prior["S3"].model.modality_names_.index("texture")
    theta[1, 1 + k] = np.log(2.9e4)  # class "b": a flat texture kernel
    prior.save(out)
    assert main(["prior", "inspect", str(out)]) == 0
    text = capsys.readouterr().out
    assert "texture: UNINFORMATIVE for b" in text and "2.9e+04" in text
    assert "force: UNINFORMATIVE" not in text


def test_learn_refuses_an_action_redefined_since_the_prior_was_built(tmp_path, capsys):
    """The prior records what each action was; an actions file that gives one of its names to
    another movement is refused instead of pairing the prior's models with other presses."""
    (tmp_path / "q.toml").write_text(
        '[[action]]\nname = "Q1"\nmovement = "press"\ndepth = 0.001\nhold_time = 0.5\n'
    )
    data, prior = tmp_path / "q.h5", tmp_path / "q.npz"
    gen = ["dataset", "generate", "-o", str(data), "--actions-file", str(tmp_path / "q.toml")]
    gen += ["--objects", "rough_sponge,metal_toolbox", "-n", "3", "--no-progress"]
    assert main(gen) == 0
    assert main(["prior", "build", str(data), "-o", str(prior)]) == 0
    recorded = PriorKnowledge.load(prior).metadata["action_definitions"]
    assert recorded["Q1"]["depth"] == 0.001
    (tmp_path / "q4.toml").write_text(
        '[[action]]\nname = "Q1"\nmovement = "press"\ndepth = 0.004\nhold_time = 0.5\n'
    )
    capsys.readouterr()
    learn = ["learn", "--robot", "sim", "--prior", str(prior), "--objects", "towel,cork_board"]
    learn += [
        "--actions-file",
        str(tmp_path / "q4.toml"),
        "--budget",
        "1",
        "-o",
        str(tmp_path / "l"),
    ]
    assert main(learn) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("aptkt learn: error: --actions-file: action 'Q1' redefines")
    assert "depth 0.001 -> 0.004" in err and "another name" in err
    assert not (tmp_path / "l").exists()


def test_a_paper_action_cannot_be_redefined(tmp_path, capsys):
    from aptkt.actions import actions_from_toml

    path = tmp_path / "p1.toml"
    path.write_text('[[action]]\nname = "P1"\nmovement = "press"\ndepth = 0.004\nhold_time = 3.0\n')
    with pytest.raises(ValueError, match=r"redefines the paper's P1 \(depth 0.001 -> 0.004\)"):
        actions_from_toml(path)
    argv = ["collect", "--robot", "sim", "--objects", "towel", "--actions", "P1", "-n", "1"]
    argv += ["--actions-file", str(path), "-o", str(tmp_path / "c.h5")]
    assert main(argv) == 1
    assert "redefines the paper's P1" in capsys.readouterr().err
    assert not (tmp_path / "c.h5").exists()
    # The same definition under the same name is no redefinition.
    path.write_text('[[action]]\nname = "P1"\nmovement = "press"\ndepth = 0.001\nhold_time = 3.0\n')
    assert actions_from_toml(path)["P1"] == PAPER_ACTIONS["P1"]


def test_a_bool_is_not_a_number_of_seconds(tmp_path):
    from aptkt.actions import ExploratoryAction, Movement, actions_from_toml

    path = tmp_path / "a.toml"
    path.write_text(
        '[[action]]\nname = "P9"\nmovement = "press"\ndepth = 0.001\nhold_time = true\n'
    )
    with pytest.raises(ValueError, match="hold_time must be a finite number >= 0, got True"):
        actions_from_toml(path)
    with pytest.raises(ValueError, match="depth must be a finite number"):
        ExploratoryAction("P9", Movement.PRESS, depth=True, hold_time=1.0)
