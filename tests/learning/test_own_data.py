"""One call from a DataFrame (or a dict of columns) to the comparison `aptkt learn --table`
runs: the same results as the command on the same rows, columns named by the user."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.errors import ConfigError, FeatureTableError
from aptkt.experiments.own_data import compare_on_data, feature_table_from
from aptkt.learning.feature_table import read_feature_table, write_feature_table

from .synthetic import draw, make_world

PRIORS, NEW = ["old0", "old1", "old2"], ["new0", "new1", "new2"]


def _file_table(tmp_path):
    priors, news, means = make_world(n_prior=3, n_new=3, related=True, seed=1)
    table = draw(means, priors + news, 4, seed=2)
    for obs in table.values():
        obs.trials = np.tile(np.arange(4), len(priors + news))
    return write_feature_table(tmp_path / "t.csv", table)


def _own_columns(path):
    """The table's rows as a user's columns: own names for everything, modalities by name."""
    t = read_feature_table(path)
    data = {"name": t.objects.tolist(), "move": t.actions.tolist(), "rep": t.trials.tolist()}
    modalities: dict[str, list[str]] = {}
    for c, column in enumerate(t.columns):
        modality, k = column.split(".")
        own = f"{modality[:3]}_{k}"
        data[own] = t.values[:, c]
        modalities.setdefault(modality, []).append(own)
    return data, modalities


class Frame:
    """A DataFrame as far as the one-call route reads one: ``columns`` and ``frame[name]``."""

    def __init__(self, data: dict) -> None:
        self._data = data
        self.columns = list(data)

    def __getitem__(self, name: str):
        return np.asarray(self._data[name])


def _cli_accuracy(path, out):
    args = ["learn", "--table", str(path), "--prior-objects", ",".join(PRIORS)]
    args += ["--objects", ",".join(NEW), "--budget", "2", "--runs", "1", "-o", str(out)]
    assert main(args) == 0
    with (out / "results.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    return {
        m: [float(r["mean_accuracy"]) for r in rows if r["method"] == m]
        for m in ("APTKT", "APTKT+aux", "baseline")
    }


def _kinds():
    kinds = [("dict", lambda d: d), ("duck-typed frame", Frame)]
    try:
        import pandas as pd
    except ImportError:
        return kinds
    return [*kinds, ("pandas", pd.DataFrame)]


@pytest.mark.parametrize("kind,make", _kinds(), ids=[k for k, _ in _kinds()])
def test_one_call_gives_the_command_s_results(tmp_path, capsys, kind, make) -> None:
    path = _file_table(tmp_path)
    expected = _cli_accuracy(path, tmp_path / "cli")
    capsys.readouterr()
    data, modalities = _own_columns(path)
    result = compare_on_data(
        make(data),
        modalities=modalities,
        object_column="name",
        action_column="move",
        trial_column="rep",
        prior_objects=PRIORS,
        new_objects=NEW,
        runs=1,
        budget=2,
    )
    assert set(result.accuracy) == set(expected)
    for method, curve in expected.items():
        assert result.accuracy[method].shape == (1, 3)  # 1 run, steps 0..budget
        np.testing.assert_allclose(result.accuracy[method][0], curve, rtol=1e-12)
    printed = str(result)
    assert "APTKT+aux" in printed and "baseline" in printed and "chance level 0.333" in printed
    assert capsys.readouterr().out == ""  # silent unless asked


def test_output_is_written_and_not_replaced_without_force(tmp_path) -> None:
    data, modalities = _own_columns(_file_table(tmp_path))
    kw = dict(
        modalities=modalities,
        object_column="name",
        action_column="move",
        trial_column="rep",
        prior_objects=PRIORS,
        new_objects=NEW,
        runs=1,
        budget=1,
        output=tmp_path / "out",
    )
    result = compare_on_data(data, **kw)
    for name in ("results.csv", "summary.json", "prior.npz", "learning_curves.png"):
        assert (tmp_path / "out" / name).is_file()
    assert str(tmp_path / "out") in str(result)
    with pytest.raises(ConfigError, match="holds an earlier result"):
        compare_on_data(data, **kw)
    compare_on_data(data, force=True, **kw)


def test_mistakes_in_the_columns_are_named() -> None:
    data = {"object": ["a", "b"], "action": ["P", "P"], "trial": [0, 0], "fx": [1.0, 2.0]}
    with pytest.raises(FeatureTableError, match=r"modality 'force' names column\(s\) \['fy'\]"):
        feature_table_from(data, {"force": ["fx", "fy"]})
    with pytest.raises(FeatureTableError, match="no column 'rep'"):
        feature_table_from(data, {"force": ["fx"]}, trial_column="rep")
    with pytest.raises(FeatureTableError, match="column fx: holds values that are not numbers"):
        feature_table_from({**data, "fx": ["1.0", "x"]}, {"force": ["fx"]})
    with pytest.raises(TypeError, match="must be a DataFrame"):
        feature_table_from([[1, 2]], {"force": ["fx"]})


def test_without_action_and_trial_columns_rows_are_numbered() -> None:
    data = {"object": ["a", "b", "a", "b"], "fx": [1.0, 2.0, 1.1, 2.1]}
    table = feature_table_from(data, {"force": ["fx"]}, action_column=None, trial_column=None)
    assert table.action_names == ["observe"]
    assert table.trials.tolist() == [0, 0, 1, 1]
    assert table.columns == ["force.0"]


def test_no_module_imports_pandas() -> None:
    """pandas stays optional: aptkt reads a frame column by column and never imports it
    (scikit-learn may, when it is installed)."""
    import ast
    from pathlib import Path

    import aptkt

    found = []
    for path in Path(aptkt.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            if any(n == "pandas" or n.startswith("pandas.") for n in names):
                found.append(f"{path.name}:{node.lineno}")
    assert not found, found


def test_an_exported_tables_extraction_column_reaches_the_learner(tmp_path) -> None:
    """A table marked as this skin's features, read back as columns (as pandas would), gives
    the command's results on the file, with this skin's transforms; asked for "other", the
    texture's activities are not log-scaled."""
    from aptkt.learning import PriorKnowledge

    priors, news, means = make_world(n_prior=3, n_new=3, related=True, seed=1)
    table = draw(means, priors + news, 4, seed=2)
    for obs in table.values():
        obs.trials = np.tile(np.arange(4), len(priors + news))
        if "texture" in obs.modalities:  # activities (variances) are positive
            obs.modalities["texture"] = np.abs(obs.modalities["texture"]) + 0.5
    path = write_feature_table(tmp_path / "t.csv", table, extraction="aptkt-skin")
    expected = _cli_accuracy(path, tmp_path / "cli")
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    data = {c: [r[c] for r in rows] for c in rows[0]}
    for c in data:
        if c not in ("object", "action", "extraction"):
            data[c] = [float(v) if v else np.nan for v in data[c]]
    kw = {"prior_objects": PRIORS, "new_objects": NEW, "runs": 1, "budget": 2}
    result = compare_on_data(data, output=tmp_path / "one-call", **kw)
    for method, curve in expected.items():
        np.testing.assert_allclose(result.accuracy[method][0], curve, rtol=1e-12)
    texture = PriorKnowledge.load(tmp_path / "one-call" / "prior.npz")["S1"].pipeline.transforms
    assert texture["texture"].log_columns == (0, 1, 2)
    compare_on_data(data, output=tmp_path / "other", extraction="other", **kw)
    other = PriorKnowledge.load(tmp_path / "other" / "prior.npz")["S1"].pipeline.transforms
    assert "texture" not in other or other["texture"].log_columns == ()
    with pytest.raises(ConfigError, match="extraction must be one of"):
        compare_on_data(data, extraction="skin", **kw)
