"""``aptkt prior``: build prior tactile knowledge from a data set, and inspect a saved one."""

from __future__ import annotations

import argparse
from pathlib import Path

from aptkt.commands._checks import (
    add_jobs_option,
    add_renamed_option,
    add_scheduler_option,
    at_least,
    at_most,
    input_file,
    intact_data_set,
    jobs,
    not_an_input,
    output_file,
    scheduler_available,
)
from aptkt.commands._inputs import (
    TABLE,
    Trials,
    add_trials_option,
    check_trials,
    dataset_trials,
    input_kind,
    parse_trials,
)
from aptkt.commands._method import add_library_model_argument
from aptkt.commands._session import object_list, split_names
from aptkt.commands.learn_table import add_extraction_argument
from aptkt.errors import ConfigError
from aptkt.files import present, strict_json
from aptkt.gp.settings import MAX_RESTARTS
from aptkt.learning.config import GPSettings
from aptkt.learning.pipeline import FEATURE_SCALES
from aptkt.progress import Progress

#: A modality's RBF kernel that varies by less than this over the training data (between the two
#: most distant observations) is effectively constant: it cannot tell observations apart, so
#: its weight γ says nothing about how informative the modality is.
CONSTANT_KERNEL_VARIATION = 0.01


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "prior", help="build, merge or inspect prior tactile knowledge (a library of objects)"
    )
    ps = p.add_subparsers(dest="prior_command", required=True, metavar="PRIOR_COMMAND")

    b = ps.add_parser(
        "build",
        help="fit the observation models of the prior (old) objects from a data set or a "
        "feature table",
        description="From a data set of this skin, extracts the features of the given objects' "
        "recordings (if not stored yet); from a feature table of any sensor "
        "(docs/feature-tables.md), reads its rows. Then fits one feature pipeline and one "
        "multi-modal Laplace GPC per action, and saves them with the observations to an .npz "
        "file (loads without executing code).",
    )
    b.add_argument(
        "data",
        type=Path,
        metavar="DATASET|TABLE",
        help="data set (HDF5) of aptkt dataset generate or aptkt collect, or a feature table "
        "(.csv, .h5)",
    )
    b.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        metavar="PRIOR",
        help="prior-knowledge file to write (.npz)",
    )
    b.add_argument("--force", action="store_true", help="replace an existing PRIOR")
    b.add_argument(
        "--objects", metavar="A,B,...", help="the prior objects (default: every object in the file)"
    )
    b.add_argument(
        "--actions", metavar="P1,S1,...", help="actions (default: every recorded action)"
    )
    add_trials_option(b)
    b.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the models' optimiser starts (default %(default)s)",
    )
    b.add_argument(
        "--restarts",
        type=int,
        default=GPSettings().n_restarts,
        metavar="N",
        help="extra optimiser starts per model (default %(default)s)",
    )
    b.add_argument(
        "--prior-feature-scale",
        choices=FEATURE_SCALES,
        default=GPSettings().prior_feature_scale,
        help="the prior's metric: whiten-joint (the within-object noise of the observations, "
        "whitened across the modalities), whiten (whitened per modality) or spread (each "
        "column z-scored over the observations); default %(default)s; docs/method.md",
    )
    add_renamed_option(b, "--feature-scale")
    add_library_model_argument(b, GPSettings().library_model)
    add_extraction_argument(b)
    add_spread_options(b)
    b.set_defaults(func=run_build)

    m = ps.add_parser(
        "merge",
        help="merge prior-knowledge files into one library (e.g. the objects a run learned)",
        description="Puts the objects of several prior-knowledge files into one library and "
        "refits its metric and models on all their observations together. The files must "
        "agree on actions, feature columns, extraction settings, metric and action "
        "definitions, and share no object; the library records where each object came from "
        "(prior inspect --json shows it). See docs/method.md.",
    )
    m.add_argument(
        "files",
        type=Path,
        nargs="+",
        metavar="PRIOR",
        help="prior-knowledge files (.npz), two or more",
    )
    m.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        metavar="PRIOR",
        help="the library to write (.npz)",
    )
    m.add_argument("--force", action="store_true", help="replace an existing output file")
    m.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the models' optimiser starts (default %(default)s)",
    )
    add_spread_options(m)
    m.set_defaults(func=run_merge)

    i = ps.add_parser("inspect", help="summarise a prior-knowledge file")
    i.add_argument("file", type=Path, metavar="PRIOR", help="prior-knowledge file (.npz)")
    i.add_argument("--json", action="store_true", help="print the summary as JSON")
    i.set_defaults(func=run_inspect)


#: A library of fewer objects is calibrated here, in a moment, whatever --jobs says: starting
#: worker processes would take longer.
SPREAD_FROM_OBJECTS = 200


def add_spread_options(parser: argparse.ArgumentParser) -> None:
    """-j and --scheduler: where a library's calibrations are computed."""
    add_jobs_option(
        parser,
        "compute the library's calibrations (the same-object cut-off's threshold, "
        f"recognition's: seconds per thousand objects; from {SPREAD_FROM_OBJECTS} objects on)",
    )
    add_scheduler_option(parser)


def spread(args: argparse.Namespace, objects: int):
    """The executor of --jobs / --scheduler for a library of ``objects`` objects, or None to
    compute here."""
    if args.scheduler is None and (args.jobs == 1 or objects < SPREAD_FROM_OBJECTS):
        return None
    from aptkt.experiments.executors import make_executor

    return make_executor(args.jobs, args.scheduler)


def save_library(prior, path: Path, executor) -> None:
    """Compute what a library file carries (its calibrations), with progress, then write it."""
    with Progress(prior.precompute_parts(), "part", "calibrating the library") as bar:
        try:
            prior.precompute(None if executor is None else executor.imap_unordered, bar)
        finally:
            if executor is not None:
                executor.close()
    prior.save(path)


def run_build(args: argparse.Namespace) -> int:
    from aptkt.learning.dataset import load_observations, stored_actions
    from aptkt.learning.extract import ExtractionSettings
    from aptkt.learning.pipeline import transforms_of

    trials = parse_trials(args.trials)
    from_table = input_kind(args.data) == TABLE
    if not from_table:
        intact_data_set(args.data, "DATASET")
        if args.extraction != "auto":
            raise ConfigError(
                f"--extraction: only for a feature table; {args.data} is a data set of this "
                "skin, whose features this package extracts"
            )
    at_least(args.seed, 0, "--seed")
    at_least(args.restarts, 0, "--restarts")
    at_most(args.restarts, MAX_RESTARTS, "--restarts", "restarts bound every model's fit")
    # Before the features are extracted and the models fitted: not after.
    output_file(args.output)
    not_an_input(args.output, "--output", {"DATASET|TABLE": args.data})
    if present(args.output) and not args.force:
        raise ConfigError(f"--output {args.output}: exists (give --force to replace it)")
    jobs(args.jobs)
    scheduler_available(args.scheduler)
    objects = split_names(args.objects, "--objects")
    if objects is not None and len(objects) < 2:
        raise ConfigError("--objects: prior knowledge needs at least two objects")
    if from_table:
        table, columns, extraction = _from_table(
            args.data, split_names(args.actions, "--actions"), objects, trials
        )
    else:
        recorded_trials = dataset_trials(args.data)
        check_trials(trials, recorded_trials, args.data)
        table = load_observations(
            args.data,
            actions=split_names(args.actions, "--actions"),
            objects=objects,
            trials=None if trials is None else [t for t in recorded_trials if t in trials],
            progress=True,
        )
    empty = [a for a, obs in table.items() if len(obs) == 0]
    if empty:
        raise ConfigError(f"no observations of {empty} for the chosen objects/trials")
    # Only now, with the input read and checked: the library's module loads scikit-learn.
    from aptkt.learning import GPSettings, PriorKnowledge

    with Progress(len(table), "action", "fitting") as bar:
        prior = PriorKnowledge.build(
            table,
            gp=GPSettings(
                n_restarts=args.restarts,
                prior_feature_scale=args.prior_feature_scale,
                library_model=args.library_model,
            ),
            # A feature table's groups get this skin's transforms only if it holds this skin's
            # features (its extraction column, or --extraction).
            transforms=transforms_of(extraction, args.extraction) if from_table else None,
            seed=args.seed,
            progress=bar,
        )
    if from_table:
        # Which columns the features are, so that libraries of other tables do not merge.
        prior.metadata.update(
            table=str(args.data),
            trials=None if trials is None else str(trials),
            feature_table_columns=columns,
        )
    else:
        # What each action was, so that `learn` refuses an actions file that gives one of these
        # names to another movement.
        recorded = stored_actions(args.data)
        prior.metadata.update(
            data=str(args.data),
            trials=None if trials is None else str(trials),
            action_definitions={a: recorded[a].to_dict() for a in prior.actions if a in recorded},
            extraction=ExtractionSettings().to_dict(),
        )
    save_library(prior, args.output, spread(args, len(prior.objects)))
    print(
        f"{args.output}: prior knowledge of {len(prior.objects)} objects ({object_list(prior.objects)}) "
        f"for {len(prior.actions)} actions"
    )
    return 0


def _from_table(
    path: Path, actions: list[str] | None, objects: list[str] | None, trials: Trials | None
):
    """A feature table's observations of the chosen actions, objects and trials, each
    action's feature columns by modality, and what extracted them (its extraction column)."""
    import numpy as np

    from aptkt.experiments.table_limits import read_table_within_limits
    from aptkt.learning.feature_table import table_columns

    table = read_table_within_limits(path, library=True)
    check_trials(trials, table.trials.tolist(), path)
    names = actions or table.action_names
    rows = np.ones(len(table.objects), dtype=bool)
    if objects is not None:
        missing = [o for o in objects if o not in set(table.object_names)]
        if missing:
            raise ConfigError(
                f"--objects: {', '.join(missing)} not in {path} (it has {', '.join(table.object_names)})"
            )
        rows &= np.isin(table.objects, objects)
    if trials is not None:
        rows &= trials.mask(table.trials)
    observations = table.observations(names, rows)
    for action, obs in observations.items():
        if len(set(obs.objects.tolist())) < 2:
            raise ConfigError(
                f"{path}: action {action} has {len(set(obs.objects.tolist()))} object(s) with "
                "the chosen objects and trials; prior knowledge needs at least two"
            )
    return observations, {a: table_columns(table, a) for a in names}, table.extraction


def load_prior(path: Path, option: str):
    """A prior-knowledge file, checked as it is read (one line naming the file otherwise)."""
    input_file(path, option)  # (before scikit-learn loads with the library's module)
    from aptkt.learning import PriorKnowledge

    try:
        return PriorKnowledge.load(path)
    except (ValueError, KeyError, OSError) as exc:
        raise ConfigError(str(exc) if str(path) in str(exc) else f"{path}: {exc}") from None


def run_merge(args: argparse.Namespace) -> int:
    import hashlib

    from aptkt.commands._checks import no_duplicates
    from aptkt.learning.library import merge_priors

    if len(args.files) < 2:
        raise ConfigError("PRIOR: merging needs at least two prior-knowledge files")
    no_duplicates([str(p.resolve()) for p in args.files], "PRIOR")
    at_least(args.seed, 0, "--seed")
    jobs(args.jobs)
    scheduler_available(args.scheduler)
    output_file(args.output)
    if present(args.output) and not args.force:
        raise ConfigError(f"--output {args.output}: exists (give --force to replace it)")
    libraries = [(str(p), load_prior(p, "PRIOR")) for p in args.files]
    digests = {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in args.files}
    first = libraries[0][1]
    with Progress(len(first.actions), "action", "fitting") as bar:
        merged = merge_priors(libraries, seed=args.seed, digests=digests, progress=bar)
    save_library(merged, args.output, spread(args, len(merged.objects)))
    counts = ", ".join(f"{name}: {len(p.objects)}" for name, p in libraries)
    print(
        f"{args.output}: a library of {len(merged.objects)} objects ({counts}) for "
        f"{len(merged.actions)} action(s), refitted on their {sum(len(a.observations) for a in merged.actions.values())} "
        "observations"
    )
    return 0


def run_inspect(args: argparse.Namespace) -> int:
    prior = load_prior(args.file, "FILE")
    rows = prior.summary()
    for r in rows:
        r["uninformative"] = uninformative_modalities(prior[r["action"]])
    if args.json:
        print(
            strict_json(
                {"objects": prior.objects, "metadata": prior.metadata, "actions": rows}, indent=2
            )
        )
        return 0
    print(f"{args.file}: {len(prior.objects)} prior objects: {object_list(prior.objects)}")
    metric = {
        "whiten-joint": "the old objects' within-object noise, whitened across the modalities",
        "whiten": "the old objects' within-object noise, whitened per modality",
        "spread": "each column z-scored over the old objects' observations",
    }
    scale = prior.feature_scale
    print(f"  feature space: {metric.get(scale, scale)}")
    plain = {
        k: v
        for k, v in prior.metadata.items()
        if not isinstance(v, dict) and k not in ("provenance", "merged_from")
    }
    if plain:
        print("  " + ", ".join(f"{k}={v}" for k, v in plain.items()))
    provenance = prior.metadata.get("provenance")
    if isinstance(provenance, list) and provenance:
        parts = [
            f"{p.get('source')} ({object_list(list(p.get('objects', [])))})"
            for p in provenance
            if isinstance(p, dict)
        ]
        print(f"  merged from: {'; '.join(parts)} (details: --json)")
    for r in rows:
        mods = ", ".join(
            f"{m} (weight {w:.2f}, length-scale {ls:.3g})"
            for m, w, ls in zip(r["modalities"], r["weights_mean"], r["length_scales_mean"])
        )
        lml = r["log_marginal_likelihood"]
        if len(r["kernel_objects"]) < len(r["objects"]):
            # Beyond the limits of aptkt.learning.locality the kernel is learned on a sample.
            learned = (
                f"kernel learned on {len(r['kernel_objects'])} of its {len(r['objects'])} "
                f"objects ({r['kernel_observations']} observations, drawn at random); "
                f"log marginal likelihood per sampled object {lml}"
            )
        else:
            learned = f"log marginal likelihood per object {lml}"
        print(f"  {r['action']}: {r['observations']} observations; {mods}; {learned}")
        for m, info in r["uninformative"].items():
            print(
                f"    {m}: UNINFORMATIVE for {', '.join(info['objects'])} — the length-scale "
                f"(up to {info['length_scale']:.3g}) is far beyond the data's range "
                f"({info['range']:.3g}), so the kernel is effectively constant whatever its weight"
            )
    return 0


def uninformative_modalities(action_prior) -> dict[str, dict]:
    """Modalities whose kernel is effectively constant over the prior's own observations for
    some objects' classifiers: ``1 - exp(-d_max^2 / (2 l^2)) < CONSTANT_KERNEL_VARIATION`` with
    ``d_max`` the largest distance between two observations in that modality's features."""
    import numpy as np

    # The observations the model's kernel was learned on (a sample beyond the limits of
    # aptkt.learning.locality: the distances of every two observations of a large library
    # would not fit in memory).
    X, groups = action_prior.features(action_prior.observations.take(action_prior.sample_rows))
    model = action_prior.model
    scales = np.atleast_2d(model.length_scales_)
    out = {}
    for k, name in enumerate(model.modality_names_):
        Z = X[:, groups[name]]
        sq = np.sum(Z**2, axis=1)
        d2 = float(np.max(sq[:, None] + sq[None, :] - 2 * Z @ Z.T, initial=0.0))
        variation = 1.0 - np.exp(-max(d2, 0.0) / (2.0 * scales[:, k] ** 2))
        flat = [str(c) for c, v in zip(model.classes_, variation) if v < CONSTANT_KERNEL_VARIATION]
        if flat:
            out[name] = {
                "objects": flat,
                "length_scale": float(scales[variation < CONSTANT_KERNEL_VARIATION, k].max()),
                "range": float(np.sqrt(max(d2, 0.0))),
            }
    return out
