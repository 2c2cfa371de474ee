"""Checks of command-line values made before a command does any work: a mistake found after a
minute of simulation (or after the arm moved) costs the user that minute, and one found by the
operating system deep inside a library reads as a traceback. Every failure is a
:class:`~aptkt.errors.ConfigError` naming the option and the value."""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

from aptkt.errors import ConfigError


def at_least(value: float | None, minimum: float, option: str) -> None:
    """``value >= minimum`` (``None``: the option was not given)."""
    if value is not None and not value >= minimum:
        raise ConfigError(f"{option} must be >= {minimum}, got {value}")


def no_duplicates(names: Iterable[str], option: str) -> None:
    twice = sorted(n for n, k in Counter(names).items() if k > 1)
    if twice:
        raise ConfigError(f"{option}: {', '.join(twice)} given more than once")


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


def output_file(path: str | Path, option: str = "--output") -> Path:
    """A file the command will create or replace: not a directory, not under a file, and in a
    directory this user may write in (the file is replaced by renaming a new one onto it)."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a directory (give a file name)")
    _writable(_existing_ancestor(path, option), path, option)
    return path


def output_dir(path: str | Path, option: str = "--output") -> Path:
    """A directory the command will create (or add to)."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise ConfigError(f"{option} {path}: is a file, not a directory")
        _writable(path, path, option)
    else:
        _writable(_existing_ancestor(path, option), path, option)
    return path


def input_file(path: str | Path, option: str) -> Path:
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"{option} {path}: no such file")
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a directory, not a file")
    return path


def resume_or_overwrite(resume: bool, overwrite: bool) -> None:
    if resume and overwrite:
        raise ConfigError(
            "--resume and --overwrite exclude each other (complete the file, or replace it)"
        )


def rewritable_file(path: str | Path, option: str = "FILE") -> Path:
    """An existing file the command rewrites: the new version is written beside it and renamed
    onto it, so both the file and its directory must be writable."""
    path = input_file(path, option)
    if not os.access(path, os.W_OK):
        raise ConfigError(f"{path}: the file is read-only")
    _writable(path.absolute().parent, path, option)
    return path
