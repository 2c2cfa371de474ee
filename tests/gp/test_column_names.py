"""Modalities by column name when the model is fitted to a DataFrame."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.gp import LaplaceGPC


def _data():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(24, 3))
    y = (X[:, 0] + 0.3 * X[:, 2] > 0).astype(int)
    return X, y


COLUMNS = ["force.0", "force.1", "temp"]
BY_NAME = {"force": ["force.0", "force.1"], "thermal": ["temp"]}
BY_INDEX = {"force": [0, 1], "thermal": [2]}


def _frame(X: np.ndarray):
    pd = pytest.importorskip("pandas")  # optional: scikit-learn reads names from DataFrames
    return pd.DataFrame(X, columns=COLUMNS)


def test_modalities_by_column_name_fit_as_by_index() -> None:
    X, y = _data()
    named = LaplaceGPC(modalities=BY_NAME, random_state=0).fit(_frame(X), y)
    indexed = LaplaceGPC(modalities=BY_INDEX, random_state=0).fit(X, y)
    assert list(named.feature_names_in_) == COLUMNS
    assert named.modality_names_ == ["force", "thermal"]
    assert [list(g) for g in named.modalities_] == [[0, 1], [2]]
    np.testing.assert_allclose(named.theta_, indexed.theta_)
    np.testing.assert_allclose(named.predict_proba(_frame(X)), indexed.predict_proba(X))


def test_column_names_with_an_array_are_a_type_error() -> None:
    X, y = _data()
    with pytest.raises(TypeError, match="X has no column names"):
        LaplaceGPC(modalities=BY_NAME).fit(X, y)


def test_an_unknown_column_name_is_named() -> None:
    X, y = _data()
    with pytest.raises(ValueError, match=r"no column\(s\) \['torque'\]; its columns are"):
        LaplaceGPC(modalities={"force": ["torque"]}).fit(_frame(X), y)


def test_names_and_indices_do_not_mix() -> None:
    X, y = _data()
    with pytest.raises(TypeError, match="mixes column names and indices"):
        LaplaceGPC(modalities={"force": ["force.0", 1]}).fit(_frame(X), y)


def test_an_array_after_a_frame_forgets_the_names() -> None:
    X, y = _data()
    model = LaplaceGPC(modalities=BY_NAME).fit(_frame(X), y)
    model.set_params(modalities=BY_INDEX).fit(X, y)
    assert not hasattr(model, "feature_names_in_")
