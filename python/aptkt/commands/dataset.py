"""``aptkt dataset``: generate data sets on the simulated world, inspect and repair data set files."""

from __future__ import annotations

import argparse
import json

from aptkt.commands._checks import (
    add_jobs_option,
    add_renamed_option,
    at_least,
    input_file,
    intact_data_set,
    jobs,
    not_an_input,
    output_file,
    resume_or_force,
    rewritable_file,
    trial_plan,
)
from aptkt.commands._inputs import add_trials_option, check_trials, parse_trials, refuse_data_set
from aptkt.commands._session import add_noise_option, noise_level, split_names
from aptkt.errors import ConfigError
from aptkt.files import present
from aptkt.progress import Progress


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("dataset", help="generate, inspect and repair data sets (HDF5)")
    ds = p.add_subparsers(dest="dataset_command", required=True, metavar="DATASET_COMMAND")

    g = ds.add_parser(
        "generate",
        help="simulate a data set: the paper's test set by default, or any objects/actions/repetitions",
        description="Simulate exploratory actions on the simulated world and store the recordings. "
        "Without --objects/--actions this is the paper's test set: each of the 7 actions 20 times "
        "on each of the 15 objects (§5.2). The same seed gives the same data, bit for bit, whatever "
        "--jobs is.",
    )
    g.add_argument(
        "-o", "--output", required=True, metavar="DATASET", help="data set to write (HDF5)"
    )
    g.add_argument(
        "--objects", metavar="A,B,...", help="object names (default: every object of the library)"
    )
    g.add_argument(
        "--objects-file",
        action="append",
        default=[],
        metavar="TOML",
        help="extra object library (repeatable); its objects join the package's",
    )
    g.add_argument("--actions", metavar="P1,S1,...", help="paper action names (default: all 7)")
    g.add_argument("--actions-file", metavar="TOML", help="your own actions ([[action]] tables)")
    g.add_argument(
        "-n",
        "--repetitions",
        type=int,
        default=20,
        metavar="N",
        help="trials per object and action (default %(default)s)",
    )
    g.add_argument(
        "--first-trial",
        type=int,
        default=0,
        metavar="K",
        help="number of the first trial (default %(default)s)",
    )
    g.add_argument(
        "--seed", type=int, default=0, metavar="N", help="world seed (default %(default)s)"
    )
    add_noise_option(g)
    add_jobs_option(g, "simulate")
    g.add_argument(
        "--resume",
        action="store_true",
        help="complete an existing file (repairs it if its writer died)",
    )
    g.add_argument("--force", action="store_true", help="replace an existing file")
    add_renamed_option(g, "--overwrite")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    g.set_defaults(func=run_generate)

    i = ds.add_parser(
        "info",
        help="summarise a data set file",
        description="Counts the recordings, and reports damage: a file cut short is checked "
        "recording by recording; --check reads every recording and stored feature (about 8 ms "
        "per recording) to find damage anywhere.",
    )
    i.add_argument("file", metavar="DATASET", help="data set (HDF5)")
    i.add_argument("--json", action="store_true", help="print the summary as JSON")
    i.add_argument(
        "--check",
        action="store_true",
        help="read everything: find a recording or feature damaged in the middle of the file",
    )
    i.set_defaults(func=run_info)

    f = ds.add_parser(
        "features", help="extract every recording's feature observation and store it in the file"
    )
    f.add_argument("file", metavar="DATASET", help="data set (HDF5); the features are stored in it")
    f.add_argument(
        "--actions", metavar="P1,S1,...", help="only these actions (default: all recorded)"
    )
    add_jobs_option(f, "extract")
    f.add_argument("--no-progress", action="store_true", help="no progress bar")
    f.set_defaults(func=run_features)

    x = ds.add_parser(
        "export-features",
        help="write the feature observations as a feature table (CSV or HDF5) for aptkt learn --table",
        description="One row per recording: object, action, trial, extraction (aptkt-skin: this "
        "skin's features, so that learning from the table transforms them as from the data set) "
        "and the feature columns <modality>.<k> (see docs/feature-tables.md). Features not yet "
        "stored are extracted first.",
    )
    x.add_argument("file", metavar="DATASET", help="data set (HDF5)")
    x.add_argument(
        "-o", "--output", required=True, metavar="TABLE", help="table to write (.csv, .h5)"
    )
    x.add_argument(
        "--actions", metavar="P1,S1,...", help="only these actions (default: all recorded)"
    )
    x.add_argument("--objects", metavar="A,B,...", help="only these objects (default: all)")
    x.add_argument("--force", action="store_true", help="replace an existing TABLE")
    x.add_argument("--no-progress", action="store_true", help="no progress bar")
    x.set_defaults(func=run_export_features)

    im = ds.add_parser(
        "import",
        help="turn a public tactile data set into a feature table (for aptkt learn --table)",
        description="Read a public data set's raw files and write one feature-table row per "
        "trial (docs/feature-tables.md). biotac-slide: the BioTac sliding set of 20 materials "
        "x 50 trials (GitHub dexrob/BioTac_slide_20_50; give the clone or its raw_data folder); "
        "its features are described in docs/real-data.md.",
    )
    im.add_argument("format", choices=["biotac-slide"], help="which data set DIR holds")
    im.add_argument("directory", metavar="DIR", help="the data set's folder")
    im.add_argument(
        "-o", "--output", required=True, metavar="TABLE", help="table to write (.csv, .h5)"
    )
    im.add_argument(
        "--materials", metavar="A,B,...", help="only these materials (default: every one found)"
    )
    im.add_argument(
        "--modalities",
        metavar="A,B,...",
        help="only these modalities (biotac-slide: vibration, pressure, temperature, electrodes; "
        "default: all)",
    )
    im.add_argument("--force", action="store_true", help="replace an existing TABLE")
    im.add_argument("--no-progress", action="store_true", help="no progress bar")
    im.set_defaults(func=run_import)

    fn = ds.add_parser(
        "fit-noise",
        help="fit the simulated world's noise to a real sensor's feature table",
        description="Measure the table's noise (how far apart its objects lie in units of the "
        "noise, how much a run of trials drifts, how much the noise differs from object to "
        "object; docs/simulation.md) and find the simulated world's noise level that matches it, "
        "by simulating probe data sets (the library's objects and the 7 paper actions, the "
        "table's trials per object up to 40; a few minutes each on 2 cores). Writes a noise "
        "level file for 'aptkt dataset generate --noise' and 'aptkt reproduce --noise'.",
    )
    fn.add_argument("table", metavar="TABLE", help="feature table of a real sensor (.csv, .h5)")
    fn.add_argument(
        "-o", "--output", required=True, metavar="NOISE", help="noise level file to write (.toml)"
    )
    add_trials_option(fn, "rows")
    fn.add_argument(
        "--probes",
        type=int,
        default=3,
        metavar="N",
        help="probe data sets to simulate; the closest is the fit (default %(default)s)",
    )
    fn.add_argument(
        "--probe-trials",
        type=int,
        metavar="N",
        help="trials per object and action in a probe (default: the table's, from 8 to 40)",
    )
    fn.add_argument(
        "--seed", type=int, default=0, metavar="N", help="world seed (default %(default)s)"
    )
    add_jobs_option(fn, "simulate")
    fn.add_argument("--force", action="store_true", help="replace an existing NOISE file")
    fn.add_argument("--json", action="store_true", help="print the fit as JSON")
    fn.set_defaults(func=run_fit_noise)

    r = ds.add_parser(
        "repair",
        help="make a file whose writer died appendable again (keeps every complete recording)",
    )
    r.add_argument("file", metavar="DATASET", help="data set (HDF5) to repair in place")
    r.add_argument(
        "--no-backup", action="store_true", help="do not keep the original as DATASET.crashed"
    )
    r.set_defaults(func=run_repair)


def build_plan(args: argparse.Namespace):  # -> GenerationPlan
    from aptkt.actions import PAPER_ACTIONS, actions_from_toml
    from aptkt.runtime.generation import GenerationPlan
    from aptkt.sim.objects import load_library

    at_least(args.seed, 0, "--seed")
    at_least(args.first_trial, 0, "--first-trial")
    at_least(args.repetitions, 1, "--repetitions")
    jobs(args.jobs)
    resume_or_force(args.resume, args.force)
    output_file(args.output)
    not_an_input(
        args.output,
        "--output",
        {"--objects-file": args.objects_file, "--actions-file": args.actions_file},
    )
    for path in args.objects_file or ():
        input_file(path, "--objects-file")  # (a device or FIFO would be read for ever)
    library = load_library(*args.objects_file)
    objects = split_names(args.objects, "--objects") or list(library)
    unknown = [o for o in objects if o not in library]
    if unknown:
        raise ConfigError(
            f"--objects: unknown object(s) {', '.join(unknown)}; known: {', '.join(library)}"
        )
    if args.actions_file:
        try:
            available = actions_from_toml(args.actions_file)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"--actions-file: {exc}") from None
    else:
        available = dict(PAPER_ACTIONS)
    names = split_names(args.actions, "--actions") or list(available)
    unknown = [a for a in names if a not in available]
    if unknown:
        raise ConfigError(
            f"--actions: unknown action(s) {', '.join(unknown)}; known: {', '.join(available)}"
        )
    trial_plan(len(objects), len(names), args.repetitions, args.first_trial)
    return GenerationPlan(
        tuple(objects),
        tuple(available[a] for a in names),
        args.repetitions,
        args.seed,
        args.first_trial,
        tuple(str(f) for f in args.objects_file),
        world_options={"noise": noise_level(args.noise).to_dict()},
    )


def run_generate(args: argparse.Namespace) -> int:
    from aptkt.runtime.generation import describe_summary, dumps, generate

    plan = build_plan(args)
    info = generate(
        args.output,
        plan,
        jobs=args.jobs,
        resume=args.resume,
        overwrite=args.force,
        progress=not args.no_progress,
    )
    print(dumps(info) if args.json else describe_summary(info))
    return 0


def run_info(args: argparse.Namespace) -> int:
    from aptkt.data import DatasetReader

    input_file(args.file, "DATASET")
    with DatasetReader(args.file) as rd:
        info = rd.info(full=args.check)
    if args.json:
        print(json.dumps(info, indent=2, sort_keys=True, default=str))
        return 0
    if info["holds_nothing"]:
        print(
            f"{info['path']}: holds nothing ({info['file_bytes']} bytes): its writer was killed "
            "as it created it, before any recording; --resume (or 'aptkt dataset repair "
            f"{args.file}') starts it afresh"
        )
        return 0
    print(f"{info['path']}: {info['schema']} (written by aptkt {info['software_version']})")
    print(
        f"  {info['recordings']} recordings, {info['samples']} samples, {info['recorded_seconds']:.1f} s recorded"
    )
    if info["damaged"]:
        shown = ", ".join(info["damaged"][:10]) + (", ..." if len(info["damaged"]) > 10 else "")
        print(
            f"  DAMAGED: {len(info['damaged'])} recording(s) cannot be read ({shown}); "
            f"'aptkt dataset repair {args.file}' keeps the {info['recordings']} readable ones"
        )
    if info["lost"]:
        print(
            f"  DAMAGED: {info['lost']} more recording(s) were indexed past the end of the file "
            "(cut short): even their names are lost"
        )
    for problem in info["damaged_features"]:
        print(
            f"  DAMAGED: stored features {problem}; they are refused when read "
            f"('aptkt dataset repair {args.file}', then extract them again)"
        )
    if info["incomplete"]:
        print(
            f"  {info['incomplete']} more recording was being appended when its writer stopped "
            "(left out)"
        )
    if info["writer"]:
        from aptkt.data.lock import describe

        print(f"  being written now by {describe(info['writer'])}")
    elif info["writer_died"]:
        print(
            "  its writer died without closing it: readable as it is; run "
            f"'aptkt dataset repair {args.file}' before appending to it"
        )
    print(
        f"  {info['file_bytes'] / 1e6:.2f} MB on disk, {info['bytes_per_sample']:.2f} bytes per sample"
    )
    if info["objects"]:
        width = max(map(len, info["objects"]))
        print("  objects:")
        for name, n in info["objects"].items():
            print(f"    {name:<{width}}  {n}")
        print("  actions: " + ", ".join(f"{a} {n}" for a, n in info["actions"].items()))
    if info["features"]:
        print(
            "  features: " + "; ".join(f"{a}: {', '.join(m)}" for a, m in info["features"].items())
        )
    desc = info.get("description") or {}
    if "seed" in desc:
        print(
            f"  generated on the simulated world, seed {desc['seed']}, {desc.get('repetitions')} repetitions"
        )
    return 0


def run_features(args: argparse.Namespace) -> int:
    from aptkt.data.lock import WriterLock
    from aptkt.experiments.executors import LocalExecutor
    from aptkt.learning.dataset import extract_features

    rewritable_file(args.file)
    jobs(args.jobs)
    intact_data_set(args.file, "DATASET")
    # A live writer is refused now, not after the extraction (the features are stored under
    # the data set's lock, taken again then).
    WriterLock.acquire(args.file).release()
    executor = LocalExecutor(args.jobs)
    try:
        counts = extract_features(
            args.file,
            actions=split_names(args.actions, "--actions"),
            progress=not args.no_progress,
            parallel_map=executor.imap_unordered if args.jobs > 1 else None,
        )
    finally:
        executor.close()
    print(
        f"{args.file}: features of " + ", ".join(f"{a} ({n} recordings)" for a, n in counts.items())
    )
    return 0


def run_export_features(args: argparse.Namespace) -> int:
    from aptkt.errors import DatasetError
    from aptkt.learning.dataset import load_observations
    from aptkt.learning.feature_table import write_feature_table

    input_file(args.file, "DATASET")
    intact_data_set(args.file, "DATASET")
    output_file(args.output)
    not_an_input(args.output, "--output", {"DATASET": args.file})
    if present(args.output) and not args.force:
        raise ConfigError(f"--output {args.output}: exists (give --force to replace it)")
    try:
        table = load_observations(
            args.file,
            actions=split_names(args.actions, "--actions"),
            objects=split_names(args.objects, "--objects"),
            progress=not args.no_progress,
        )
    except (DatasetError, KeyError, OSError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        raise ConfigError(msg if str(args.file) in msg else f"{args.file}: {msg}") from None
    empty = [a for a, obs in table.items() if len(obs) == 0]
    if empty:
        raise ConfigError(f"{args.file}: no observations of {', '.join(empty)} for these objects")
    # The observations say they are this skin's features, and so does the table: learning
    # from it transforms them as from the data set.
    write_feature_table(args.output, table)
    rows = sum(len(obs) for obs in table.values())
    print(f"{args.output}: {rows} rows ({', '.join(f'{a} {len(o)}' for a, o in table.items())})")
    return 0


def run_repair(args: argparse.Namespace) -> int:
    from aptkt.data import repair

    rewritable_file(args.file)
    kept = repair(args.file, backup=not args.no_backup)
    print(
        f"{args.file}: repaired, {kept} readable recordings kept"
        + ("" if args.no_backup else f" (original kept as {args.file}.crashed)")
    )
    return 0


def run_import(args: argparse.Namespace) -> int:
    from aptkt.importers.biotac_slide import find_trials, import_biotac_slide
    from aptkt.learning.feature_table import check_table_name, write_feature_table

    output = output_file(args.output)
    check_table_name(output)
    if present(output) and not args.force:
        raise ConfigError(f"--output {output}: exists (give --force to replace it)")
    materials = split_names(args.materials, "--materials")
    total = len(find_trials(args.directory))
    bar = None if args.no_progress else Progress(total, "trial", "importing")
    try:
        observations = import_biotac_slide(
            args.directory,
            materials=materials,
            modalities=split_names(args.modalities, "--modalities"),
            on_trial=None if bar is None else (lambda _trial: bar.update(1)),
        )
    finally:
        if bar is not None:
            bar.close()
    write_feature_table(output, {observations.action: observations})
    objects = observations.object_names
    print(
        f"{output}: {len(observations)} rows, action {observations.action}, "
        f"{len(objects)} materials, modalities "
        + ", ".join(
            f"{m} ({observations.modalities[m].shape[1]})" for m in observations.modality_names
        )
    )
    return 0


def run_fit_noise(args: argparse.Namespace) -> int:
    from aptkt.experiments.noise_fit import fit_noise
    from aptkt.learning.feature_table import read_feature_table
    from aptkt.sim.noise import noise_level_toml

    trials = parse_trials(args.trials)
    at_least(args.probes, 1, "--probes")
    at_least(args.probe_trials, 4, "--probe-trials")
    at_least(args.seed, 0, "--seed")
    jobs(args.jobs)
    output = output_file(args.output)
    not_an_input(output, "--output", {"TABLE": args.table})
    if present(output) and not args.force:
        raise ConfigError(f"--output {output}: exists (give --force to replace it)")
    refuse_data_set(args.table, "aptkt dataset fit-noise")
    table = read_feature_table(args.table)
    if trials is not None:
        check_trials(trials, table.trials.tolist(), args.table)
        table = table.take(trials.mask(table.trials))
    fit = fit_noise(
        table.observations(),
        probes=args.probes,
        trials=args.probe_trials,
        seed=args.seed,
        jobs=args.jobs,
        say=(lambda _: None) if args.json else print,
    )
    t, r = fit.target, fit.reached
    comments = (
        f"aptkt dataset fit-noise {args.table}: the simulated world's noise level fitted to it",
        f"the table: separation {t.separation:.2f}, drift {t.drift:.2f}, heterogeneity "
        f"{t.heterogeneity:.2f} (medians over actions and modalities)",
        f"the world at this level: separation {r.separation:.2f}, drift {r.drift:.2f}, "
        f"heterogeneity {r.heterogeneity:.2f} ({r.trials} trials per object, seed {args.seed})",
    )
    from aptkt.files import write_text_atomically

    write_text_atomically(output, noise_level_toml(fit.level, comments), ConfigError)
    if args.json:
        print(json.dumps(fit.as_dict(), indent=2))
    else:
        lv = fit.level
        print(
            f"{output}: trial {lv.trial:.3f}, drift {lv.drift:.3f}, objects {lv.objects:.3f} "
            f"(use it with --noise {output})"
        )
    return 0
