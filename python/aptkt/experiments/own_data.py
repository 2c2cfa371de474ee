"""APTKT against the baseline on a user's own data, in one call from Python.

``compare_on_data(frame, modalities={"force": ["fx", "fy"], ...}, prior_objects=...,
new_objects=...)`` turns a DataFrame (pandas or anything with ``columns`` and ``frame[name]``)
or a dict of equally long arrays into a feature table (:mod:`aptkt.learning.feature_table`),
and runs the comparison of ``aptkt learn --table``
(:func:`aptkt.experiments.table_learning.compare_on_table`). pandas is never imported: a frame
is read column by column.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError, FeatureTableError, InvalidTypeError
from aptkt.experiments.bounds import MAX_BUDGET, MAX_RUNS
from aptkt.experiments.table_learning import (
    TableSettings,
    compare_on_table,
    refuse_overwrite,
    write_table_results,
)
from aptkt.experiments.table_limits import check_size, check_table
from aptkt.learning import LearnerConfig
from aptkt.learning.feature_table import (
    EXTRACTION_COLUMN,
    ID_COLUMNS,
    FeatureTable,
    table_from_columns,
)
from aptkt.learning.pipeline import EXTRACTIONS

__all__ = ["Comparison", "compare_on_data", "feature_table_from"]

#: What messages call a table passed from Python.
_NAME = "<data>"


def _column_names(data: Any) -> list[str]:
    if isinstance(data, Mapping):
        return [str(k) for k in data]
    if hasattr(data, "columns") and hasattr(data, "__getitem__"):
        return [str(c) for c in data.columns]
    raise InvalidTypeError(
        "data must be a DataFrame (anything with .columns and frame[column]) or a dict of "
        f"column name -> values, got {type(data).__name__}"
    )


def _column(data: Any, name: str) -> np.ndarray:
    return np.asarray(data[name])


def _numbers(values: np.ndarray, name: str) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise FeatureTableError(
            f"{_NAME}, column {name}: holds values that are not numbers"
        ) from None


def feature_table_from(
    data: Any,
    modalities: Mapping[str, Sequence[str]] | None = None,
    *,
    object_column: str = "object",
    action_column: str | None = "action",
    trial_column: str | None = "trial",
    single_action: str = "observe",
) -> FeatureTable:
    """A validated feature table from a frame or a dict of columns.

    ``modalities`` maps each modality to its columns, in order (they become ``<modality>.0``,
    ``<modality>.1``, ...); other columns are left out. Without it the feature columns must be
    named ``<modality>.<k>`` already. ``action_column=None``: every row is one action named
    ``single_action``; ``trial_column=None``: rows are numbered per object and action in order.
    NaN marks a feature an action does not have, as an empty cell in a file. A column
    ``extraction`` says what computed the features, as in a file (a table that
    ``aptkt dataset export-features`` wrote, read with pandas, keeps it).
    """
    names = _column_names(data)
    for option, column in (
        ("object_column", object_column),
        ("action_column", action_column),
        ("trial_column", trial_column),
    ):
        if column is not None and column not in names:
            raise FeatureTableError(f"{_NAME}: no column {column!r} ({option}); it has {names}")
    objects = [str(v) for v in _column(data, object_column).ravel()]
    n = len(objects)
    actions = (
        [single_action] * n
        if action_column is None
        else [str(v) for v in _column(data, action_column).ravel()]
    )
    if trial_column is None:
        seen: dict[tuple[str, str], int] = {}
        trials: list = []
        for key in zip(objects, actions):
            trials.append(seen.get(key, 0))
            seen[key] = trials[-1] + 1
    else:
        trials = list(_column(data, trial_column).ravel())
    columns: dict[str, Sequence] = {"object": objects, "action": actions, "trial": trials}
    if EXTRACTION_COLUMN in names:  # what computed the features, as a table file says it
        columns[EXTRACTION_COLUMN] = [str(v) for v in _column(data, EXTRACTION_COLUMN).ravel()]
    if modalities is None:
        taken = {object_column, action_column, trial_column, EXTRACTION_COLUMN}
        features = {c: c for c in names if c not in taken}
    else:
        features = {}
        known = set(names)
        for modality, listed in modalities.items():
            if isinstance(listed, str):
                listed = [listed]
            unknown = [c for c in listed if c not in known]
            if unknown:
                raise FeatureTableError(
                    f"{_NAME}: modality {modality!r} names column(s) {unknown} that the data "
                    f"does not have; it has {names}"
                )
            if not listed:
                raise FeatureTableError(f"{_NAME}: modality {modality!r} lists no columns")
            for k, c in enumerate(listed):
                features[f"{modality}.{k}"] = c
    # (Before the table is built: its validation compares every column with every other.)
    check_size(_NAME, n, len([c for c in features if c not in ID_COLUMNS]))
    for new, old in features.items():
        if new in ID_COLUMNS:
            continue
        columns[new] = _numbers(_column(data, old), str(old)).tolist()
    return table_from_columns(columns, _NAME)


@dataclass
class Comparison:
    """The accuracies of APTKT, APTKT with auxiliary features and the baseline, per step.

    ``accuracy[method]`` is (runs, steps): each action's model on its own held-out
    observations, averaged over actions (the paper's measure), after 0, 1, ... actively chosen
    observations; ``fused_accuracy`` combines all actions' posteriors. ``rows`` holds every
    step of every run as ``results.csv`` does."""

    accuracy: dict[str, np.ndarray]
    fused_accuracy: dict[str, np.ndarray]
    prior_objects: tuple[str, ...]
    new_objects: tuple[str, ...]
    actions: list[str]
    rows: list[dict[str, Any]] = field(repr=False)
    output: Path | None = None

    @property
    def chance(self) -> float:
        return 1.0 / len(self.new_objects)

    def __repr__(self) -> str:
        curves = next(iter(self.accuracy.values()), np.zeros((0, 0)))
        final = ", ".join(f"{m} {self.mean(m)[-1]:.3f}" for m in self.accuracy if curves.size)
        parts = [
            f"{len(self.new_objects)} new objects, {len(self.prior_objects)} prior objects",
            f"actions {', '.join(self.actions)}",
            f"{curves.shape[0]} runs of {curves.shape[1]} steps",
        ]
        if final:
            parts.append(f"final accuracy {final}")
        if self.output is not None:
            parts.append(f"files in {self.output}")
        return f"Comparison({'; '.join(parts)})"

    def mean(self, method: str, fused: bool = False) -> np.ndarray:
        """The mean over runs at each step."""
        curves = self.fused_accuracy if fused else self.accuracy
        return np.nanmean(curves[method], axis=0)

    def __str__(self) -> str:
        n = min(c.shape[1] for c in self.accuracy.values())
        marks = sorted({0, n // 4, n // 2, n - 1})
        head = f"{'method':<11}{'accuracy':<13}" + "".join(f"{f'+{m} obs':>9}" for m in marks)
        lines = [
            f"new objects {', '.join(self.new_objects)}; prior {', '.join(self.prior_objects)}; "
            f"actions {', '.join(self.actions)}",
            head,
            "-" * len(head),
        ]
        for name in self.accuracy:
            for kind, fused in (("action mean", False), ("fused", True)):
                values = self.mean(name, fused)
                cells = "".join(f"{values[m]:>9.3f}" for m in marks)
                lines.append(f"{name if not fused else '':<11}{kind:<13}{cells}")
        runs = next(iter(self.accuracy.values())).shape[0]
        lines.append(f"mean over {runs} run(s); chance level {self.chance:.3f}")
        if self.output is not None:
            lines.append(f"files: {self.output}")
        return "\n".join(lines)


def _curves(rows: list[dict[str, Any]], method: str, key: str) -> np.ndarray:
    runs = sorted({r["run"] for r in rows if r["method"] == method})
    steps = max(r["step"] for r in rows if r["method"] == method) + 1
    out = np.full((len(runs), steps), np.nan)
    for r in rows:
        if r["method"] == method:
            out[runs.index(r["run"]), r["step"]] = r[key]
    return out


def _names(value: Any, name: str, *, at_least: int = 0) -> None:
    """A sequence of distinct text names (a single string is not one: it would be read as
    its letters)."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
        raise ConfigError(f"{name} must be a list of names, got {value!r}")
    bad = [v for v in value if not isinstance(v, str) or not v]
    if bad:
        raise ConfigError(f"{name}: names must be non-empty text, got {bad[0]!r}")
    twice = sorted(v for v, k in Counter(value).items() if k > 1)
    if twice:
        raise ConfigError(f"{name}: {', '.join(twice)} given more than once")
    if len(value) < at_least:
        raise ConfigError(f"{name} must name at least {at_least}, got {list(value)!r}")


def _arguments(
    *,
    prior_objects: Any,
    new_objects: Any,
    modalities: Any,
    actions: Any,
    object_column: Any,
    action_column: Any,
    trial_column: Any,
    test_trials: Any,
    test_fraction: Any,
    runs: Any,
    config: Any,
    output: Any,
    say: Any,
    force: Any,
    extraction: Any,
    learner: Mapping[str, Any],
) -> LearnerConfig:
    """Every argument of :func:`compare_on_data` checked (a :class:`ConfigError`, or a
    ``TypeError`` for an argument of the wrong kind, naming it); the learner's settings."""
    _names(prior_objects, "prior_objects", at_least=2)
    _names(new_objects, "new_objects", at_least=2)
    if actions is not None:
        _names(actions, "actions", at_least=1)
    if modalities is not None:
        if not isinstance(modalities, Mapping) or not modalities:
            raise ConfigError(f"modalities must map modality names to columns, got {modalities!r}")
        for m, listed in modalities.items():
            if not isinstance(m, str) or not m:
                raise ConfigError(f"modalities: a modality name must be text, got {m!r}")
            if not isinstance(listed, str):
                _names(listed, f"modalities[{m!r}]", at_least=1)
    for option, column, optional in (
        ("object_column", object_column, False),
        ("action_column", action_column, True),
        ("trial_column", trial_column, True),
    ):
        if not (isinstance(column, str) or (optional and column is None)):
            raise ConfigError(
                f"{option} must be a column name{' or None' if optional else ''}, got {column!r}"
            )
    if test_trials is not None:
        if isinstance(test_trials, (str, bytes)) or not isinstance(test_trials, Sequence):
            raise ConfigError(f"test_trials must be a list of trial numbers, got {test_trials!r}")
        bad = [
            t
            for t in test_trials
            if isinstance(t, bool) or not isinstance(t, (int, np.integer)) or not 0 <= t < 2**63
        ]
        if bad or not test_trials:
            raise ConfigError(
                "test_trials must be trial numbers >= 0 (64-bit integers), got "
                f"{bad[0] if bad else test_trials!r}"
            )
    if (
        isinstance(test_fraction, bool)
        or not isinstance(test_fraction, (int, float, np.floating))
        or not 0.0 < float(test_fraction) < 1.0
    ):
        raise ConfigError(
            f"test_fraction must be a number between 0 and 1 (the share of each object's rows "
            f"held out), got {test_fraction!r}"
        )
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ConfigError(f"runs must be an integer >= 1, got {runs!r}")
    if runs > MAX_RUNS:
        raise ConfigError(f"runs must be at most {MAX_RUNS}, got {runs}")
    if config is not None and not isinstance(config, LearnerConfig):
        raise InvalidTypeError(
            f"config must be a LearnerConfig or None, got {type(config).__name__}"
        )
    if output is not None:
        if not isinstance(output, (str, Path)) or not str(output):
            raise ConfigError(f"output must be a directory's path or None, got {output!r}")
        if Path(output).exists() and not Path(output).is_dir():
            raise ConfigError(f"output {output}: is a file, not a directory")
    if say is not None and not callable(say):
        raise InvalidTypeError(f"say must be a function of one line, or None, got {say!r}")
    if not isinstance(force, bool):
        raise ConfigError(f"force must be True or False, got {force!r}")
    if not isinstance(extraction, str) or extraction not in EXTRACTIONS:
        raise ConfigError(f"extraction must be one of {EXTRACTIONS}, got {extraction!r}")
    cfg = config if config is not None else LearnerConfig()
    unknown = sorted(set(learner) - {f.name for f in fields(LearnerConfig)})
    if unknown:
        raise ConfigError(
            f"unknown argument(s) {', '.join(unknown)}: neither compare_on_data's nor a "
            "LearnerConfig setting"
        )
    defaults = {f.name: getattr(cfg, f.name) for f in fields(LearnerConfig)}
    # (A setting that may be None, aux_gate_margin say, is checked as a number when it is one.)
    may_be_none = {f.name for f in fields(LearnerConfig) if "None" in str(f.type)}
    for name, value in learner.items():
        if not (value is None and name in may_be_none):
            _like(name, value, defaults[name])
        if name in ("budget", "patience") and value is not None and value > MAX_BUDGET:
            raise ConfigError(f"{name} must be at most {MAX_BUDGET}, got {value}")
    try:
        return replace(cfg, **learner) if learner else cfg
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"learner settings: {exc}") from None


def _like(name: str, value: Any, default: Any) -> None:
    """A learner setting of the kind its default is (a count an integer, a threshold a finite
    number, a choice a string): LearnerConfig checks the values, not their kinds."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = (
            isinstance(value, (int, np.integer))
            and not isinstance(value, bool)
            and bool(value >= 0)
        )
    elif isinstance(default, float):
        ok = (
            isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool)
            and bool(np.isfinite(value))
        )
    elif isinstance(default, str):
        ok = isinstance(value, str)
    else:
        return  # (None by default, or settings of their own type: checked by LearnerConfig)
    if not ok:
        kind = {bool: "True or False", int: "an integer >= 0", float: "a finite number"}
        raise ConfigError(f"{name} must be {kind.get(type(default), 'text')}, got {value!r}")


def compare_on_data(
    data: Any,
    *,
    prior_objects: Sequence[str],
    new_objects: Sequence[str],
    modalities: Mapping[str, Sequence[str]] | None = None,
    actions: Sequence[str] | None = None,
    object_column: str = "object",
    action_column: str | None = "action",
    trial_column: str | None = "trial",
    test_trials: Sequence[int] | None = None,
    test_fraction: float = 0.5,
    runs: int = 3,
    config: LearnerConfig | None = None,
    output: str | Path | None = None,
    say: Callable[[str], None] | None = None,
    force: bool = False,
    extraction: str = "auto",
    **learner: Any,
) -> Comparison:
    """APTKT (with and without auxiliary features) against the baseline on your own data.

    The rows of ``prior_objects`` build the prior knowledge; the rows of ``new_objects`` are
    split by trial into a pool to learn from and a held-out test set (``test_trials``, or the
    later ``test_fraction`` of each object's trials per action), as ``aptkt learn --table``
    does. ``config`` (or keyword arguments such as ``budget=6, seed=0``, applied on top of
    it) sets the learner. ``extraction`` says whose features the data holds
    (:data:`~aptkt.learning.pipeline.EXTRACTIONS`, as ``--extraction`` of ``aptkt learn
    --table``): "aptkt-skin" transforms them as this skin's, "other" z-scores every column,
    "auto" reads the data's ``extraction`` column (other without one). With ``output``, the
    files of ``aptkt learn --table`` are written there too (an earlier result there is replaced
    only with ``force=True``). ``say`` receives the progress lines (default: silent). See
    :func:`feature_table_from` for ``data`` and ``modalities``.

    Every argument is checked before any work: a mistake is a
    :class:`~aptkt.errors.ConfigError` (a ``TypeError`` for ``data``, ``config`` or ``say`` of
    the wrong kind) naming it; the table is checked against
    :mod:`aptkt.experiments.table_limits`.
    """
    cfg = _arguments(
        prior_objects=prior_objects,
        new_objects=new_objects,
        modalities=modalities,
        actions=actions,
        object_column=object_column,
        action_column=action_column,
        trial_column=trial_column,
        test_trials=test_trials,
        test_fraction=test_fraction,
        runs=runs,
        config=config,
        output=output,
        say=say,
        force=force,
        extraction=extraction,
        learner=learner,
    )
    table = feature_table_from(
        data,
        modalities,
        object_column=object_column,
        action_column=action_column,
        trial_column=trial_column,
    )
    check_table(
        table,
        actions=actions,
        prior_objects=prior_objects,
        exact=config.gp.library_model == "exact" if config is not None else False,
    )
    settings = TableSettings(
        table=table.path,
        prior_objects=tuple(prior_objects),
        new_objects=tuple(new_objects),
        actions=tuple(actions) if actions else None,
        test_trials=tuple(test_trials) if test_trials is not None else None,
        test_fraction=test_fraction,
        output=Path(output) if output is not None else Path("."),
        runs=runs,
        config=cfg,
        extraction=extraction,
    )
    quiet = say if say is not None else (lambda line: None)
    t_start = time.perf_counter()
    if output is None:
        rows, _, chosen = compare_on_table(table, settings, say=quiet)
    else:
        out = refuse_overwrite(Path(output), force)
        out.mkdir(parents=True, exist_ok=True)
        rows, methods, chosen = compare_on_table(
            table, settings, say=quiet, prior_path=out / "prior.npz"
        )
        write_table_results(settings, table, rows, methods, chosen, t_start=t_start, say=quiet)
    names = list(dict.fromkeys(r["method"] for r in rows))
    return Comparison(
        accuracy={m: _curves(rows, m, "mean_accuracy") for m in names},
        fused_accuracy={m: _curves(rows, m, "fused_accuracy") for m in names},
        prior_objects=settings.prior_objects,
        new_objects=settings.new_objects,
        actions=list(chosen),
        rows=rows,
        output=Path(output) if output is not None else None,
    )
