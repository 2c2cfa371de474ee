"""Checks of command-line values made before a command does any work: a mistake found after a
minute of simulation (or after the arm moved) costs the user that minute, and one found by the
operating system deep inside a library reads as a traceback. Every failure is a
:class:`~aptkt.errors.ConfigError` naming the option and the value."""

from __future__ import annotations

import argparse
import math
import os
from collections import Counter
from collections.abc import Iterable, Mapping
from pathlib import Path

from aptkt.errors import ConfigError

# (Re-exported: the bounds of learning runs and budgets, shared with the Python entry points.)
from aptkt.experiments.bounds import MAX_BUDGET, MAX_RUNS  # noqa: F401
from aptkt.files import not_a_regular_file

#: Trials one command may plan (objects x actions x repetitions): 50 times the paper's test set
#: (2,100 trials). The plan is held in memory before the first trial runs, and a larger one
#: would run for days; split bigger collections with --first-trial.
MAX_TRIALS = 100_000
#: Seconds aptkt waits for the temperature sensors after an action (--thermal-wait): an hour.
MAX_THERMAL_WAIT = 3600.0
#: aptkt writes side files next to a data set, named after it (``.features-tmp``,
#: ``.repairing``, ``.crashed``, ``.creating``, ``.lock``, ``.aborted-<k>.h5``): a name must leave this
#: many bytes of the file system's limit for them.
SIDE_FILE_ROOM = 16


def at_least(value: float | None, minimum: float, option: str) -> None:
    """``value >= minimum`` (``None``: the option was not given)."""
    if value is not None and not value >= minimum:
        raise ConfigError(f"{option} must be >= {minimum}, got {value}")


def check_target_accuracy(value: float | None) -> None:
    """``--target-accuracy``: an accuracy in (0, 1] (``None``: not given)."""
    if value is not None and not (math.isfinite(value) and 0.0 < value <= 1.0):
        raise ConfigError(f"--target-accuracy must be an accuracy in (0, 1], got {value}")


def at_most(value: float | None, maximum: float, option: str, why: str = "") -> None:
    """``value <= maximum`` and finite (``None``: the option was not given); ``why`` says
    where the bound comes from."""
    if value is not None and not (math.isfinite(value) and value <= maximum):
        raise ConfigError(
            f"{option} must be at most {maximum:g}, got {value}" + (f" ({why})" if why else "")
        )


def max_jobs() -> int:
    """Processes a command may start (--jobs): four per core. More only share the same cores
    (the work is CPU-bound) while each holds its own copy of the simulated world."""
    return 4 * (os.cpu_count() or 1)


def add_jobs_option(parser: argparse._ActionsContainer, what: str) -> None:
    """The ``-j/--jobs N`` option every parallel command has, with one default: all cores."""
    parser.add_argument(
        "-j",
        "--jobs",
        type=int,
        default=os.cpu_count() or 1,
        metavar="N",
        help=f"{what} in N processes (default: all cores)",
    )


#: Old spellings of options, refused with the new one for one release: one word per concept
#: across the commands (runs: learning runs; trials: trial numbers; --force: replace what
#: exists; --prior-feature-scale: the prior's metric).
RENAMED_OPTIONS = {
    "--trials": "--runs",
    "--overwrite": "--force",
    "--feature-scale": "--prior-feature-scale",
}


def add_renamed_option(parser: argparse._ActionsContainer, old: str) -> None:
    """``old`` (a key of :data:`RENAMED_OPTIONS`) is refused with a hint at its new name."""
    new = RENAMED_OPTIONS[old]

    class Renamed(argparse.Action):
        def __call__(
            self,
            parser: argparse.ArgumentParser,
            namespace: argparse.Namespace,
            values: object,
            option_string: str | None = None,
        ) -> None:
            parser.error(f"{old} is now {new} (the same meaning in every command)")

    parser.add_argument(
        old, nargs="?", action=Renamed, help=argparse.SUPPRESS, dest=argparse.SUPPRESS
    )


def add_scheduler_option(parser: argparse._ActionsContainer) -> None:
    """``--scheduler ADDRESS``: the same option wherever work can run on a Dask cluster."""
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on a Dask distributed cluster (e.g. tcp://host:8786); the data and the output "
        "directory must be on a file system the workers share",
    )


def scheduler_available(address: str | None) -> None:
    """With ``--scheduler``, Dask's distributed scheduler must be installed, and the address
    must answer as a Dask scheduler does (both checked before any work)."""
    if not address:
        return
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise ConfigError(
            "--scheduler needs dask[distributed]: pip install 'aptkt[dask]'"
        ) from None
    from aptkt.experiments.executors import check_scheduler

    check_scheduler(address)


def jobs(value: int, option: str = "--jobs") -> None:
    at_least(value, 1, option)
    at_most(value, max_jobs(), option, f"4 per core of this machine's {os.cpu_count() or 1}")


def trial_plan(objects: int, actions: int, repetitions: int, first_trial: int) -> None:
    """A plan of ``repetitions`` trials of every action on every object, numbered from
    ``first_trial``, within :data:`MAX_TRIALS` and
    :data:`aptkt.data.schema.MAX_TRIAL_NUMBER`."""
    from aptkt.data.schema import MAX_TRIAL_NUMBER  # (aptkt.data loads h5py: not at start-up)

    total = objects * actions * repetitions
    if total > MAX_TRIALS:
        raise ConfigError(
            f"--repetitions {repetitions}: {objects} object(s) x {actions} action(s) x "
            f"{repetitions} = {total} trials, more than the {MAX_TRIALS} one command may plan "
            "(split the work into several files with --first-trial)"
        )
    if first_trial + repetitions - 1 > MAX_TRIAL_NUMBER:
        raise ConfigError(
            f"--first-trial {first_trial} with --repetitions {repetitions}: trial numbers "
            f"must stay below {MAX_TRIAL_NUMBER + 1} (a data set stores them as 32-bit integers)"
        )


def no_duplicates(names: Iterable[str], option: str) -> None:
    twice = sorted(n for n, k in Counter(names).items() if k > 1)
    if twice:
        raise ConfigError(f"{option}: {', '.join(twice)} given more than once")


def known_names(names: Iterable[str] | None, available: Iterable[str], option: str) -> None:
    """Every name given to ``option`` is one of ``available`` (the table's actions, say)."""
    known = list(available)
    unknown = [n for n in names or () if n not in known]
    if unknown:
        raise ConfigError(
            f"{option}: unknown {', '.join(unknown)}; the table has {', '.join(known)}"
        )


def _existing_ancestor(path: Path, option: str) -> Path:
    """The deepest existing directory above ``path``; an error if a file lies on the way."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"{option} {path}: {parent} is a file, not a directory")
            return parent
    return Path("/")


def _writable(directory: Path, path: Path, option: str) -> None:
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {path}: cannot write in {directory} (permission denied)")


def _limit(directory: Path, name: str, default: int) -> int:
    try:
        return int(os.pathconf(directory, name))
    except (OSError, ValueError):
        return default


def _short(path: Path) -> str:
    text = str(path)
    return text if len(text) <= 60 else f"{text[:30]}...{text[-20:]}"


def name_fits(path: str | Path, option: str, *, room: int = 0, path_room: int = 0) -> None:
    """Every component of ``path`` within the file system's limit (``room`` bytes fewer for the
    last, which names the side files too), and the whole path, plus ``path_room`` bytes for
    what the command puts under it, within the system's: the operating system would refuse the
    name only once the command opens the file, after its work."""
    path = Path(path)
    where = Path("/")
    for parent in path.absolute().parents:
        if os.path.isdir(parent):
            where = parent
            break
    name_max = _limit(where, "PC_NAME_MAX", 255)
    path_max = _limit(where, "PC_PATH_MAX", 4096)
    parts = path.parts
    for i, part in enumerate(parts):
        size = len(os.fsencode(part))
        last = i == len(parts) - 1
        if size > name_max - (room if last else 0):
            extra = (
                f", less {room} for the side files aptkt names after it" if last and room else ""
            )
            raise ConfigError(
                f"{option} {_short(path)}: a name of {size} bytes is too long (the file system "
                f"allows {name_max} bytes per name{extra})"
            )
    size = len(os.fsencode(str(path.absolute())))
    if size + max(room, path_room) >= path_max:
        raise ConfigError(
            f"{option} {_short(path)}: a path of {size} bytes is too long (the system allows "
            f"{path_max - 1} bytes, less {max(room, path_room)} for the files aptkt adds)"
        )


def output_file(path: str | Path, option: str = "--output") -> Path:
    """A file the command will create or replace: a name the file system takes, not a
    directory, not under a file, and in a directory this user may write in (the file is
    replaced by renaming a new one onto it)."""
    name_fits(path, option, room=SIDE_FILE_ROOM)
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a directory (give a file name)")
    _regular(path, option)
    _writable(_existing_ancestor(path, option), path, option)
    return path


def not_an_input(
    output: str | Path, option: str, inputs: Mapping[str, str | Path | Iterable | None]
) -> None:
    """Writing ``output`` must not destroy what the command reads: refused, with or without
    --force, when it names one of ``inputs`` (``{option or argument: path or paths}``; links
    followed), which a command would read and then replace with something else."""
    target = os.path.realpath(output)
    for name, given in inputs.items():
        paths = [given] if isinstance(given, (str, Path)) else list(given or ())
        for path in paths:
            if os.path.realpath(path) == target:
                raise ConfigError(
                    f"{option} {output}: is the input {name} {path}; writing there would "
                    "destroy what this command reads (give another name)"
                )


def _regular(path: Path, option: str) -> None:
    """Only regular files are ours: a device, a FIFO or a socket under the name is neither
    read (it may block, or never end) nor renamed away and replaced by a file."""
    kind = not_a_regular_file(path)
    if kind is not None:
        raise ConfigError(
            f"{option} {path}: is {kind}, not a regular file (aptkt reads and writes only "
            "regular files)"
        )


def output_dir(path: str | Path, option: str = "--output") -> Path:
    """A directory the command will create (or add to)."""
    # The files inside have names of aptkt's choosing; 64 bytes covers the longest of them.
    name_fits(path, option, path_room=64)
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise ConfigError(f"{option} {path}: is a file, not a directory")
        _writable(path, path, option)
        _holds_only_files(path, option)
    else:
        _writable(_existing_ancestor(path, option), path, option)
    return path


#: What the names of the files aptkt writes into an output directory end in (results, plots,
#: data, and their temporary versions).
_RESULT_SUFFIXES = (".md", ".json", ".jsonl", ".csv", ".png", ".svg", ".npz", ".h5", ".tmp")


def _holds_only_files(directory: Path, option: str) -> None:
    """An output directory holds no device, FIFO or socket named as aptkt's files are
    (``*.json``, ``*.csv``, ...): aptkt would block on one, or replace it, when it writes its
    results there. (Others, a database's socket in /tmp say, are none of aptkt's business.)"""
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return  # (what cannot be listed is reported when it is written)
    for entry in entries:
        if not entry.name.endswith(_RESULT_SUFFIXES) or entry.is_dir() or entry.is_file():
            continue
        kind = not_a_regular_file(entry.path)
        if kind is not None and kind != "a directory":
            raise ConfigError(
                f"{option} {directory}: holds {entry.name}, {kind}; aptkt writes its results "
                "only among regular files: choose another directory"
            )


def input_file(path: str | Path, option: str) -> Path:
    name_fits(path, option)
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"{option} {path}: no such file")
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a directory, not a file")
    _regular(path, option)
    return path


def intact_data_set(path: str | Path, option: str) -> None:
    """A data set file that holds recordings and is not cut short, or whose shortened end
    damaged nothing: bytes past the end of a file read as zeros, and a command must not learn
    from those. (Damage in the middle of a file is found when the damaged recording or feature
    is read.)"""
    from aptkt.data import DatasetReader
    from aptkt.learning.feature_table import is_feature_table

    where = f"{option} {path}" if option.startswith("-") else str(path)
    if is_feature_table(path):
        # (The data set reader would say "not a readable HDF5 data set", of a CSV file.)
        raise ConfigError(
            f"{where}: is a feature table, not a data set (HDF5) of this skin; a table is read "
            "as the DATASET|TABLE of prior build and recognise, or the TABLE of learn and benchmark"
        )
    with DatasetReader(path) as rd:
        problem = rd.damage() if rd.cut_short else None
        empty = len(rd) == 0 and not rd.lost
        left_empty = rd.holds_nothing
    if empty and not problem:
        raise ConfigError(
            f"{where}: holds no recordings"
            + (" (its writer was killed as it created it)" if left_empty else "")
            + "; there is nothing to read"
        )
    if problem:
        raise ConfigError(
            f"{where}: damaged (the file is cut short): {problem}; 'aptkt dataset repair "
            f"{path}' keeps every readable recording"
        )


def resume_or_force(resume: bool, force: bool) -> None:
    if resume and force:
        raise ConfigError(
            "--resume and --force exclude each other (complete the file, or replace it)"
        )


def rewritable_file(path: str | Path, option: str = "FILE") -> Path:
    """An existing file the command rewrites: the new version is written beside it and renamed
    onto it, so both the file and its directory must be writable."""
    path = input_file(path, option)
    if not os.access(path, os.W_OK):
        raise ConfigError(f"{path}: the file is read-only")
    _writable(path.absolute().parent, path, option)
    return path
