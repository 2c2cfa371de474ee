"""Learning from a feature table (``aptkt learn --table``): any sensor's observations, the demo's
comparison.

The prior objects' rows build the prior knowledge; the new objects' rows are split into a pool
to learn from and a held-out test set (by trial number); APTKT, APTKT with auxiliary features and
the baseline then learn the new objects ``runs`` times each, as in the demo, and the same files
are written (:func:`aptkt.experiments.demo.report_results`): ``results.csv`` (every step of
every run), ``learning_curves.png``/``.svg``, ``confusion.png``/``.svg``/``.csv`` (the final
models, baseline and APTKT), ``transfer_APTKT.png``/``transfer_APTKT_aux.png`` (and ``.svg``:
the relatedness heat-maps), ``report.md``, ``summary.json`` (settings, table, accuracies,
transfer lines) and ``prior.npz``.
"""

from __future__ import annotations

import platform
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.errors import ConfigError, FeatureTableError
from aptkt.experiments.demo import report_results
from aptkt.experiments.runs import step_rows
from aptkt.experiments.table_limits import read_table_within_limits
from aptkt.files import present
from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge
from aptkt.learning.feature_table import FeatureTable, split_held_out
from aptkt.learning.pipeline import transforms_of

__all__ = [
    "TableSettings",
    "compare_on_table",
    "learn_from_table",
    "read_settings_table",
    "refuse_overwrite",
    "write_table_results",
]


@dataclass
class TableSettings:
    table: Path
    prior_objects: tuple[str, ...]
    new_objects: tuple[str, ...]
    actions: tuple[str, ...] | None = None
    test_trials: tuple[int, ...] | None = None
    test_fraction: float = 0.5
    output: Path = Path("aptkt-learn")
    runs: int = 3
    #: APTKT's learner (its budget, seed and method choices); APTKT+aux adds the auxiliary
    #: features, the baseline uses no prior.
    config: LearnerConfig = field(default_factory=LearnerConfig)
    #: Whose features the table holds (:data:`~aptkt.learning.pipeline.EXTRACTIONS`): "auto"
    #: reads the table's ``extraction`` column.
    extraction: str = "auto"
    #: The trials the table was restricted to (as ``--trials`` reads them), for the record:
    #: the rows are chosen by whoever passes the table to :func:`learn_from_table`.
    trials: str | None = None


def _check_objects(table, s: TableSettings, actions: list[str]) -> None:
    known = set(table.object_names)
    for option, names in (("prior", s.prior_objects), ("new", s.new_objects)):
        unknown = [o for o in names if o not in known]
        if unknown:
            raise FeatureTableError(
                f"{table.path}: no rows of {option} object(s) {', '.join(unknown)}; "
                f"the table has {', '.join(table.object_names)}"
            )
    both = sorted(set(s.prior_objects) & set(s.new_objects))
    if both:
        raise FeatureTableError(f"object(s) {', '.join(both)} are both prior and new")
    if len(s.prior_objects) < 2 or len(s.new_objects) < 2:
        raise FeatureTableError("learning needs at least two prior and two new objects")
    for obj in s.prior_objects:
        for action in actions:
            if table.rows_of(obj, action).size == 0:
                raise FeatureTableError(
                    f"{table.path}: prior object {obj} has no rows of action {action}"
                )


#: The files of a comparison's result, its report and plots too: one of them in the output
#: directory means a file would be replaced (a user's own report.md as much as ours).
RESULT_FILES = (
    "summary.json",
    "results.csv",
    "prior.npz",
    "report.md",
    "learning_curves.png",
    "learning_curves.svg",
    "confusion.png",
    "confusion.svg",
    "confusion.csv",
)


def refuse_overwrite(
    out: Path, force: bool, how: str = "force=True", where: str | None = None
) -> Path:
    """``out``, unless it holds a result already and ``force`` is not given. ``how``: the
    caller's way to give ``force``; ``where``: how messages name ``out``."""
    found = [name for name in RESULT_FILES if present(out / name)]
    if found and not force:
        raise ConfigError(
            f"{where or out} holds an earlier result ({', '.join(found)}); give {how} to "
            "replace it, or choose another output directory"
        )
    return out


def compare_on_table(
    table: FeatureTable, s: TableSettings, *, say=print, prior_path: Path | None = None
) -> tuple[list[dict[str, Any]], dict[str, LearnerConfig], list[str]]:
    """The comparison itself, on a table read or built in memory: the step rows of every run
    of every method, the methods' learner settings and the actions learnt. With
    ``prior_path`` the prior knowledge is saved there."""
    actions = list(s.actions) if s.actions else table.action_names
    unknown = [a for a in actions if a not in set(table.action_names)]
    if unknown:
        raise FeatureTableError(
            f"{table.path}: no rows of action(s) {', '.join(unknown)}; "
            f"the table has {', '.join(table.action_names)}"
        )
    _check_objects(table, s, actions)
    pool_rows, test_rows = split_held_out(
        table, actions, s.new_objects, test_trials=s.test_trials, test_fraction=s.test_fraction
    )
    prior_rows = np.isin(table.objects, list(s.prior_objects))
    say(
        f"[1/3] {table.path}: {len(table.trials)} rows; actions {', '.join(actions)}; "
        f"{int(pool_rows.sum())} rows to learn from and {int(test_rows.sum())} held out"
    )
    to = f" -> {prior_path}" if prior_path is not None else ""
    say(f"[2/3] building prior knowledge on {', '.join(s.prior_objects)}{to}")
    cfg = s.config
    # This skin's transforms only for this skin's features: a group named "texture" in
    # another sensor's table is not this skin's texture.
    transforms = transforms_of(table.extraction, s.extraction)
    prior = PriorKnowledge.build(
        table.observations(actions, prior_rows), gp=cfg.gp, seed=cfg.seed, transforms=transforms
    )
    if prior_path is not None:
        prior.save(prior_path)
    pool = table.observations(actions, pool_rows)
    test = table.observations(actions, test_rows)
    methods = {
        "APTKT": replace(cfg, transfer="paper", auxiliary=False),
        "APTKT+aux": replace(cfg, transfer="paper", auxiliary=True),
        "baseline": replace(cfg, transfer="none", auxiliary=False),
    }
    say(
        f"[3/3] learning {', '.join(s.new_objects)}: APTKT (with and without auxiliary features) "
        f"vs baseline, {s.runs} runs each, budget {cfg.budget}"
    )
    rows: list[dict[str, Any]] = []
    for t in range(s.runs):
        for name, method in methods.items():
            learner = APTKT(replace(method, seed=cfg.seed + t), prior, transforms=transforms)
            run = learner.run(
                PoolEnvironment(pool, seed=cfg.seed + t), actions, s.new_objects, test
            )
            steps = step_rows(run, learner, s.new_objects)
            rows += [{"method": name, "run": t, **r} for r in steps]
    return rows, methods, actions


def learn_from_table(
    s: TableSettings, *, say=print, table: FeatureTable | None = None
) -> dict[str, Any]:
    """The comparison on the table file ``s.table`` (or on ``table``, some of its rows, read
    already with :func:`read_settings_table`), with every file of the demo's results written
    to ``s.output``; returns the summary."""
    t_start = time.perf_counter()
    if table is None:
        table = read_settings_table(s)
    out = Path(s.output)
    out.mkdir(parents=True, exist_ok=True)
    rows, methods, actions = compare_on_table(table, s, say=say, prior_path=out / "prior.npz")
    return write_table_results(s, table, rows, methods, actions, t_start=t_start, say=say)


def read_settings_table(s: TableSettings) -> FeatureTable:
    """The table ``s.table``, read within the limits of learning from it with ``s``."""
    return read_table_within_limits(
        s.table,
        prior_objects=s.prior_objects,
        actions=s.actions,
        exact=s.config.gp.library_model == "exact",
    )


def write_table_results(
    s: TableSettings,
    table: FeatureTable,
    rows: list[dict[str, Any]],
    methods: dict[str, LearnerConfig],
    actions: list[str],
    *,
    t_start: float,
    say=print,
) -> dict[str, Any]:
    """The demo's result files of a comparison in ``s.output`` (its ``prior.npz`` saved
    already); returns the summary."""
    out = Path(s.output)
    prior_path = out / "prior.npz"
    cfg = s.config
    settings = {
        k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(s).items() if k != "config"
    }
    return report_results(
        out,
        rows,
        methods,
        tuple(s.new_objects),
        budget=cfg.budget,
        title=(
            f"{table.path.name}: {len(s.new_objects)} new objects, "
            f"priors: {', '.join(s.prior_objects)}"
        ),
        head={
            "software_version": __version__,
            "python": platform.python_version(),
            "settings": settings,
            "actions": actions,
            "learner": {name: m.to_dict() for name, m in methods.items()},
        },
        size="table",
        files={"table": str(table.path), "prior": str(prior_path)},
        t_start=t_start,
        say=say,
    )
