"""``aptkt collect``: record a data set on the UR10 (or the simulated world) with the skin."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from aptkt.commands._checks import (
    add_renamed_option,
    at_least,
    not_an_input,
    output_file,
    resume_or_force,
    trial_plan,
)
from aptkt.commands._session import (
    EXIT_FAULT,
    add_action_arguments,
    add_session_arguments,
    available_actions,
    make_session,
    pick_actions,
    session_inputs,
    split_names,
)
from aptkt.errors import ConfigError
from aptkt.files import present


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "collect",
        help="collect a data set: exploratory actions on objects, with the UR10 or the simulated world",
        description="Apply every action N times to every object and store each recording in a crash-safe "
        "HDF5 data set, trial by trial (a killed run keeps every completed trial; --resume completes the "
        "file). On a robot or skin fault the arm is stopped, the partial recording goes to "
        f"<output>.aborted.h5, and the command exits with code {EXIT_FAULT} naming the object, action "
        "and trial.",
    )
    add_session_arguments(p)
    p.add_argument(
        "--objects",
        required=True,
        metavar="A,B,...",
        help="objects to explore (workspace or world names)",
    )
    add_action_arguments(p, default_help="default: the paper's seven")
    p.add_argument(
        "-n",
        "--repetitions",
        type=int,
        required=True,
        metavar="N",
        help="trials per object and action",
    )
    p.add_argument(
        "--first-trial",
        type=int,
        default=0,
        metavar="K",
        help="number of the first trial (default %(default)s)",
    )
    p.add_argument(
        "-o", "--output", required=True, metavar="DATASET", help="data set to write (HDF5)"
    )
    p.add_argument(
        "--resume", action="store_true", help="complete an existing file: skip the trials it holds"
    )
    p.add_argument("--force", action="store_true", help="replace an existing file")
    add_renamed_option(p, "--overwrite")
    p.add_argument(
        "--prompt-between-trials",
        action="store_true",
        help="wait for Enter before each new trial round (re-place the objects by hand, paper §5.2)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="world seed for --robot sim (default %(default)s)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def _prompt(trial: int) -> None:
    print(
        f"\nTrial {trial}: re-place the objects as for a new trial, then press Enter (Ctrl-C stops) ",
        end="",
        file=sys.stderr,
        flush=True,
    )
    if not sys.stdin.readline():
        raise ConfigError("--prompt-between-trials: standard input closed")


def run(args: argparse.Namespace) -> int:
    from aptkt.runtime.collection import CollectionAborted, CollectionPlan, collect

    at_least(args.repetitions, 1, "--repetitions")
    at_least(args.first_trial, 0, "--first-trial")
    at_least(args.seed, 0, "--seed")
    resume_or_force(args.resume, args.force)
    output_file(args.output)
    not_an_input(args.output, "--output", session_inputs(args))
    objects = split_names(args.objects, "--objects") or []  # a required option
    available = available_actions(args)
    names = split_names(args.actions, "--actions") or list(available)
    trial_plan(len(objects), len(names), args.repetitions, args.first_trial)
    plan = CollectionPlan(
        tuple(objects), tuple(pick_actions(names, available)), args.repetitions, args.first_trial
    )
    session = make_session(args, seed=args.seed)
    session.check_objects(plan.objects)
    session.check_actions(plan.actions, plan.objects)
    if present(args.output) and not (args.resume or args.force):
        # Before the arm moves, not after.
        raise ConfigError(
            f"{args.output} exists: use --resume to complete it or --force to replace it"
        )
    progress: bool | Callable[[str], None]
    if args.no_progress:
        progress = False
    elif sys.stderr.isatty():
        progress = True
    else:
        progress = _print_line

    try:
        with session:
            info = collect(
                args.output,
                plan,
                session,
                resume=args.resume,
                overwrite=args.force,
                progress=progress,
                between_trials=_prompt if args.prompt_between_trials else None,
            )
    except CollectionAborted as exc:
        print(f"aptkt collect: fault: {exc}", file=sys.stderr)
        return EXIT_FAULT
    print(
        f"{args.output}: {info['collected']} recordings collected now, {info['skipped']} already there; "
        f"{info['recordings']} in the file ({info['samples']} samples, {info['recorded_seconds']:.1f} s recorded) "
        f"in {info['wall_seconds']:.1f} s"
        + (
            f"; repaired a crashed file first ({info['repaired']} recordings kept)"
            if info.get("repaired")
            else ""
        )
    )
    return 0


def _print_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)
