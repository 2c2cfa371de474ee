"""``aptkt learn``: learn new objects live with APTKT, on the UR10 (or the simulated world)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from aptkt.commands import learn_table
from aptkt.commands._checks import (
    MAX_BUDGET,
    at_least,
    at_most,
    check_target_accuracy,
    input_file,
    intact_data_set,
    not_an_input,
    output_dir,
    output_file,
)
from aptkt.commands._method import add_method_arguments, learner_config
from aptkt.commands._session import (
    EXIT_FAULT,
    add_action_arguments,
    add_session_arguments,
    available_actions,
    make_session,
    object_list,
    pick_actions,
    session_inputs,
    split_names,
)
from aptkt.errors import ConfigError
from aptkt.files import present
from aptkt.learning.config import EXPLORATION, LearnerConfig
from aptkt.learning.transfer import TRANSFER_MODES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "learn",
        help="learn new objects with APTKT (active exploration, prior knowledge transfer): live "
        "on the UR10 or the simulated world, or offline from a feature table (learn TABLE, or --table TABLE)",
        description="Explore new objects with the robot, choosing each next action and object by the "
        "models' uncertainty and transferring prior tactile knowledge (paper §4). Every recording is kept "
        "(--record); the run (steps, transfer decisions, settings) goes to --output as JSON and CSV, and the "
        "new objects' observations and models to OUTPUT/learned_prior.npz, usable later as --prior. A live "
        "run has no test set: accuracy is reported only with --test DATASET. Given a feature table "
        "(aptkt learn TABLE ...), it learns offline from the table instead (below).",
    )
    p.add_argument(
        "input",
        nargs="?",
        metavar="TABLE",
        help="a feature table (.csv, .h5) to learn from offline; none: learn live (--robot)",
    )
    add_session_arguments(p, robot_required=False)  # required unless a table is given
    p.add_argument(
        "--prior",
        metavar="PRIOR",
        help="prior-knowledge file (.npz, of aptkt prior build; required unless TABLE)",
    )
    p.add_argument(
        "--objects",
        required=True,
        metavar="A,B,...",
        help="the new objects to learn (at least two)",
    )
    add_action_arguments(p, default_help="default: every action of the prior knowledge")
    p.add_argument(
        "--budget",
        type=int,
        default=LearnerConfig.budget,
        metavar="N",
        help="observations chosen actively after the initial round (default %(default)s)",
    )
    p.add_argument(
        "--eps-neg",
        type=float,
        default=LearnerConfig.eps_neg,
        metavar="E",
        help="transfer cut-off ε_neg (default %(default)s)",
    )
    p.add_argument(
        "--eps-explor",
        type=float,
        default=None,
        metavar="E",
        help="probability of a random (action, object) pick, ε_explor (default: the rule's "
        f"own, {', '.join(f'{v:g} for {k}' for k, v in EXPLORATION.items() if k != 'random')})",
    )
    p.add_argument(
        "--transfer",
        choices=TRANSFER_MODES,
        default=None,
        help="paper: APTKT's transfer (Eq. 2-3); none: the baseline (nothing of the prior); control: the prior's feature space without "
        "transfer (default paper)",
    )
    p.add_argument(
        "--auxiliary",
        action="store_true",
        help="add the prior models' posteriors as a modality (Eq. 5)",
    )
    add_method_arguments(p)
    p.add_argument(
        "--patience",
        type=int,
        default=None,
        metavar="N",
        help="stop early after N observations without lower mean uncertainty (default: spend the budget)",
    )
    p.add_argument(
        "--target-accuracy",
        type=float,
        default=None,
        metavar="A",
        help="stop early once the learner's own estimate of its mean accuracy reaches A (every "
        "touch is judged before it is learned; default: spend the budget)",
    )
    p.add_argument(
        "--record",
        metavar="DATASET",
        help="data set receiving every recording (default OUTPUT/recordings.h5; appended to if it exists)",
    )
    p.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("aptkt-learn"),
        metavar="DIR",
        help="output directory (default %(default)s)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an earlier result in --output (live: run.json, steps.csv, transfer.csv, "
        "learned_prior.npz; --table: summary.json, results.csv, prior.npz)",
    )
    p.add_argument(
        "--recognise",
        action="store_true",
        help="live: first touch each of --objects once with every action and recognise it with "
        "the --prior library; learn only the objects it flags as new (docs/recognition.md)",
    )
    p.add_argument(
        "--merge-into",
        type=Path,
        metavar="PRIOR",
        help="live: when the run ends, write the --prior library with the newly learned objects "
        "merged in (refitted on all their observations, provenance recorded; aptkt prior "
        "merge) to this file; refused before the robot moves if the run does not learn every "
        "action of the library",
    )
    p.add_argument(
        "--test",
        metavar="DATASET",
        help="data set (HDF5) of the same objects and actions: report test accuracy",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=LearnerConfig.seed,
        metavar="N",
        help="seed of the learner (and of the simulated world) (default %(default)s)",
    )
    learn_table.add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from aptkt.learning import PriorKnowledge
    from aptkt.runtime.live_learning import LiveLearningAborted, learn_live

    option = "--table" if args.table is not None else "TABLE"
    args.table = _table(args)
    if args.table:
        if args.recognise:
            raise ConfigError(
                "--recognise: only for a live run (--robot); a table's touches are recognised with aptkt recognise"
            )
        if args.merge_into is not None:
            raise ConfigError(
                "--merge-into: only for a live run (--robot); a table's objects become a library "
                "with aptkt prior merge"
            )
        from aptkt.commands._inputs import refuse_data_set

        refuse_data_set(args.table, "aptkt learn", option, prior_option="--prior")
        return learn_table.run(args)
    for option, value in (("--robot", args.robot), ("--prior", args.prior)):
        if not value:
            raise ConfigError(f"{option} is required (or learn offline: aptkt learn TABLE ...)")
    offline = learn_table.table_only(args)
    if offline:
        raise ConfigError(f"{', '.join(offline)}: only when learning from a table (learn TABLE)")
    args.transfer = args.transfer or "paper"

    _refuse_earlier_run(args.output, args.force)  # before anything is loaded or checked
    input_file(args.prior, "--prior")
    if args.merge_into is not None:
        output_file(args.merge_into, "--merge-into")
        own = [n for n in RUN_FILES if _same_file(args.merge_into, args.output / n)]
        if own:
            raise ConfigError(
                f"--merge-into {args.merge_into}: is the run's own {own[0]} in --output "
                f"{args.output}; merge into a file of its own"
            )
        if present(args.merge_into) and not args.force:
            raise ConfigError(
                f"--merge-into {args.merge_into}: exists (give --force to replace it)"
            )
    at_least(args.seed, 0, "--seed")
    at_least(args.budget, 0, "--budget")
    at_most(args.budget, MAX_BUDGET, "--budget")
    at_least(args.patience, 1, "--patience")
    at_most(args.patience, MAX_BUDGET, "--patience")
    check_target_accuracy(args.target_accuracy)
    output_dir(args.output)
    if args.record:
        output_file(args.record, "--record")
        not_an_input(args.record, "--record", {**session_inputs(args), "--prior": args.prior})
        if Path(args.record).is_symlink():  # the record file is appended to, in place
            raise ConfigError(
                f"--record {args.record}: is a symbolic link; aptkt appends to no file through "
                "a link (give the file itself, or another name)"
            )
    try:
        prior = PriorKnowledge.load(args.prior)
    except (OSError, ValueError, KeyError) as exc:
        raise ConfigError(f"--prior {args.prior}: cannot load prior knowledge: {exc}") from None
    objects = split_names(args.objects, "--objects") or []  # a required option
    if len(objects) < 2:
        raise ConfigError("--objects: learning needs at least two new objects")
    overlap = sorted(set(objects) & set(prior.objects))
    if overlap and not args.recognise:
        raise ConfigError(
            f"--objects: {', '.join(overlap)} already in the prior knowledge ({args.prior})"
        )
    names = split_names(args.actions, "--actions") or list(prior.actions)
    missing = [a for a in names if a not in prior]
    if missing:
        raise ConfigError(
            f"--actions: the prior knowledge has no experience of {', '.join(missing)}; "
            f"it has {', '.join(prior.actions)}"
        )
    _skin_features(prior, names, args.prior)
    actions = {a.name: a for a in pick_actions(names, available_actions(args))}
    _same_as_the_prior(actions, prior.metadata.get("action_definitions"), args.prior)
    unlearned = [a for a in prior.actions if a not in actions]
    if args.merge_into is not None and unlearned:
        raise ConfigError(
            f"--merge-into: the library {args.prior} holds action(s) {', '.join(unlearned)} that "
            "this run does not learn; the merged library would lack the new objects there "
            "(learn every action, or merge later with aptkt prior merge)"
        )
    try:
        config = learner_config(
            args,
            **({} if args.eps_neg is None else {"eps_neg": args.eps_neg}),
            eps_explor=args.eps_explor,
            budget=args.budget,
            transfer=args.transfer,
            auxiliary=args.auxiliary,
            patience=args.patience,
            target_accuracy=args.target_accuracy,
            seed=args.seed,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    test = None
    if args.test:
        input_file(args.test, "--test")
        intact_data_set(args.test, "--test")
        test = _load_test(args.test, names, objects)
    session = make_session(args, seed=args.seed)
    session.check_objects(objects)
    session.check_actions(actions.values(), objects)
    record = Path(args.record) if args.record else args.output / "recordings.h5"

    def report(line: str) -> None:
        print(line, flush=True)

    report(
        f"learning {', '.join(objects)} with {', '.join(actions)} on {args.robot}; prior objects: "
        f"{object_list(prior.objects)}; transfer {args.transfer}"
        + (" + auxiliary features" if args.auxiliary else "")
        + f"; budget {args.budget}, eps_neg {config.eps_neg}, selection {config.selection} "
        f"(eps_explor {config.exploration:g}), seed {args.seed}"
    )
    try:
        with session:
            learn_live(
                session,
                prior,
                config,
                actions,
                objects,
                record=record,
                output=args.output,
                test=test,
                report=report,
                extra={
                    "prior": {"path": str(args.prior)},
                    "test": {"path": args.test} if args.test else {},
                },
                recognise_first=args.recognise,
            )
    except LiveLearningAborted as exc:
        print(f"aptkt learn: fault: {exc}", file=sys.stderr)
        if args.merge_into is not None:
            print(
                f"aptkt learn: {args.merge_into} not written (the run did not finish)",
                file=sys.stderr,
            )
        return EXIT_FAULT
    if args.merge_into is not None:
        _merge_learned(
            args.prior, prior, args.output / "learned_prior.npz", args.merge_into, report
        )
    return 0


def _merge_learned(
    library_path: str, library: Any, learned_path: Path, target: Path, report: Any
) -> None:
    """The library with the run's new objects merged in (:func:`aptkt.learning.library.
    merge_priors`), written to ``target``."""
    import hashlib

    from aptkt.learning import PriorKnowledge
    from aptkt.learning.library import merge_priors

    if not learned_path.exists():
        raise ConfigError(f"--merge-into: the run wrote no {learned_path}; nothing to merge")
    learned = PriorKnowledge.load(learned_path)
    digests = {
        str(p): hashlib.sha256(Path(p).read_bytes()).hexdigest()
        for p in (library_path, learned_path)
    }
    merged = merge_priors(
        [(str(library_path), library), (str(learned_path), learned)], digests=digests
    )
    from aptkt.commands.prior import save_library

    save_library(merged, target, None)
    report(
        f"{target}: the library of {len(merged.objects)} objects ({len(library.objects)} from "
        f"{library_path}, {len(learned.objects)} learned now)"
    )


def _table(args: argparse.Namespace) -> str | None:
    """The feature table of an offline run: TABLE, or --table as it was written before."""
    if args.input is not None and args.table is not None:
        raise ConfigError(f"{args.input} and --table {args.table}: give the table once, as TABLE")
    return args.input if args.input is not None else args.table


#: What a live run writes to its output directory (its recordings are appended to).
RUN_FILES = ("run.json", "steps.csv", "transfer.csv", "learned_prior.npz")


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file, whether it exists yet or not (links followed)."""
    return os.path.realpath(a) == os.path.realpath(b)


def _refuse_earlier_run(out: Path, force: bool) -> None:
    found = [name for name in RUN_FILES if present(out / name)]
    if found and not force:
        raise ConfigError(
            f"--output {out}: holds an earlier result ({', '.join(found)}); give --force to "
            "replace it, or choose another output directory"
        )


def _skin_features(prior: Any, actions: list[str], path: Any) -> None:
    """A live run observes with this skin's feature extraction: a library of another sensor's
    or another extraction's features (a feature table's columns) cannot be compared with them,
    and failed deep inside a transform with a shape mismatch."""
    from aptkt.learning.pipeline import SKIN_EXTRACTION

    foreign = [a for a in actions if prior[a].observations.extraction != SKIN_EXTRACTION]
    if foreign:
        table = prior.metadata.get("table")
        source = f" (built from {table})" if table else ""
        raise ConfigError(
            f"--prior {path}: its action(s) {', '.join(foreign)} hold features of another "
            f"sensor or extraction{source}, not this skin's; a live run needs a library of "
            "this skin's recordings (aptkt prior build DATASET, or a table exported with "
            "aptkt dataset export-features)"
        )


def _same_as_the_prior(actions: dict, recorded: object, path: str) -> None:
    """Refuses an action whose definition differs from the one of the same name the prior
    knowledge was built with (recorded by ``aptkt prior build``): its models would be paired
    with observations of another movement."""
    from aptkt.actions import ExploratoryAction
    from aptkt.actions.definition import redefinition

    if not isinstance(recorded, dict):
        return  # a prior built otherwise: only the paper's names are known (actions_from_toml)
    try:
        known = {name: ExploratoryAction.from_dict(d) for name, d in recorded.items()}
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"--prior {path}: its recorded action definitions: {exc}") from None
    for action in actions.values():
        why = redefinition(action, known, "the action the prior knowledge was built with,")
        if why:
            raise ConfigError(f"--actions-file: {why} (prior {path})")


def _load_test(path: str, actions: list[str], objects: list[str]):  # -> ObservationTable
    from aptkt.errors import DatasetError
    from aptkt.learning.dataset import load_observations

    try:
        table = load_observations(path, actions=actions, objects=objects)
    except (DatasetError, KeyError, OSError) as exc:
        raise ConfigError(f"--test {path}: {exc}") from None
    for action, obs in table.items():
        missing = [o for o in objects if o not in set(obs.objects.tolist())]
        if missing:
            raise ConfigError(
                f"--test {path}: no observations of action {action} on {', '.join(missing)}"
            )
    return table
