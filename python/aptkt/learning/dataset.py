"""Feature observations from recorded data sets (HDF5, :mod:`aptkt.data`).

:func:`extract_features` computes every recording's feature observation once and stores it in
the file (``/features/<action>/<modality>``), keyed by the extraction settings; this is the one
function that writes. :func:`load_observations` reads them back as an observation table; it
uses stored features only when they were extracted with the settings asked for, and otherwise
extracts in memory, never writing into the file it reads.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.actions import ExploratoryAction
from aptkt.data import DatasetError, DatasetReader, store_features
from aptkt.errors import InvalidStateError
from aptkt.learning.extract import ExtractionSettings, observe_recording
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import SKIN_EXTRACTION
from aptkt.progress import Progress
from aptkt.skin.samples import Recording

__all__ = ["extract_features", "load_observations", "stored_actions", "stale_features"]


def stored_actions(path: str | Path) -> dict[str, ExploratoryAction]:
    """The actions recorded in a data set, with their parameters as recorded."""
    actions: dict[str, ExploratoryAction] = {}
    with DatasetReader(path) as rd:
        for i in range(len(rd)):
            _, name, _ = rd.key(i)
            if name not in actions:
                actions[name] = ExploratoryAction.from_dict(rd.metadata(i)["action"])
    return actions


def _rows_by_action(rd: DatasetReader, wanted: Iterable[str] | None) -> dict[str, list[int]]:
    names = None if wanted is None else set(wanted)
    by_action: dict[str, list[int]] = {}
    for i in range(len(rd)):
        _, name, _ = rd.key(i)
        if names is None or name in names:
            by_action.setdefault(name, []).append(i)
    missing = (names or set()) - set(by_action)
    if missing:
        raise DatasetError(
            f"{rd.path} holds no recordings of action(s) {', '.join(sorted(missing))}; "
            f"it has {', '.join(sorted({rd.key(i)[1] for i in range(len(rd))}))}"
        )
    return by_action


def _recording(rd: DatasetReader, i: int) -> Recording:
    try:
        return rd.recording(i)
    except (OSError, ValueError) as exc:
        obj, name, trial = rd.key(i)
        raise DatasetError(
            f"{rd.path}: recording {i} ({obj}/{name}/trial {trial}) is damaged "
            f"({exc}); 'aptkt dataset repair {rd.path}' keeps the readable ones"
        ) from None


def _extract(
    rd: DatasetReader,
    by_action: dict[str, list[int]],
    settings: ExtractionSettings,
    progress: bool,
    desc: str,
) -> dict[str, dict[str, np.ndarray]]:
    """Feature values per action and modality, one row per recording of ``by_action``."""
    total = sum(len(v) for v in by_action.values())
    bar = Progress(total, "recording", desc) if progress else None
    values: dict[str, dict[str, np.ndarray]] = {}
    try:
        for name, rows in by_action.items():
            action = ExploratoryAction.from_dict(rd.metadata(rows[0])["action"])
            per_mod: dict[str, list[np.ndarray]] = {m: [] for m in action.modalities}
            for i in rows:
                obs = observe_recording(_recording(rd, i), action, settings)
                for m, v in obs.items():
                    per_mod[m].append(v)
                if bar is not None:
                    bar.update(1)
            values[name] = {m: np.stack(v) for m, v in per_mod.items()}
    finally:
        if bar is not None:
            bar.close()
    return values


def stale_features(
    path: str | Path, actions: Iterable[str], settings: ExtractionSettings | None = None
) -> list[str]:
    """Of ``actions``, those without stored features extracted with ``settings``."""
    key = (settings or ExtractionSettings()).to_dict()
    with DatasetReader(path) as rd:
        return [a for a in actions if not _features_current(rd, a, key)]


def _features_current(rd: DatasetReader, action: str, key: dict[str, Any]) -> bool:
    """Whether the stored features of ``action`` were extracted with these settings *and* cover
    every recording of it: recordings appended later (``dataset generate --resume``) have
    none, and reading the stored ones alone would silently drop them."""
    if rd.feature_settings(action) != key:
        return False
    modalities = rd.feature_names().get(action, [])
    if not modalities:
        return False
    stored = {int(i) for i in rd.features(action, modalities[0])[0]}
    return set(_rows_by_action(rd, [action]).get(action, [])) <= stored


#: Runs ``fn`` on every item elsewhere (e.g. ``LocalExecutor(jobs).imap_unordered``), yielding
#: ``(index, result)`` pairs in any order.
ParallelMap = Callable[[Callable[[Any], Any], Sequence[Any]], Iterator[tuple[int, Any]]]

#: Recordings per task when extracting in parallel: large enough that opening the file (a few
#: ms per task) is noise, small enough to keep every process busy to the end.
_CHUNK_ROWS = 32


def _extract_chunk(task: tuple[str, str, list[int], ExtractionSettings]) -> dict[str, np.ndarray]:
    """One action's feature values of some of its recordings, read from the file itself (a
    worker process opens it read-only; the file must not be open for writing)."""
    path, action, rows, settings = task
    with DatasetReader(path) as rd:
        return _extract(rd, {action: rows}, settings, False, "")[action]


def extract_features(
    path: str | Path,
    *,
    actions: Iterable[str] | None = None,
    settings: ExtractionSettings | None = None,
    progress: bool = True,
    parallel_map: ParallelMap | None = None,
) -> dict[str, int]:
    """Extract and store the feature observations of every recording (of ``actions``), keyed by
    ``settings``.

    ``parallel_map`` spreads the recordings over other processes in chunks (the stored values
    are the same as without it). Returns the number of recordings per action. The file must
    not be open for writing.
    """
    path = Path(path)
    settings = settings or ExtractionSettings()
    with DatasetReader(path) as rd:
        by_action = _rows_by_action(rd, actions)
        if parallel_map is None:
            values = _extract(rd, by_action, settings, progress, f"features {path.name}")
    if parallel_map is not None:
        values = _extract_in_chunks(path, by_action, settings, progress, parallel_map)
    store_features(
        path,
        {name: (by_action[name], per_mod) for name, per_mod in values.items()},
        settings=settings.to_dict(),
    )
    return {name: len(rows) for name, rows in by_action.items()}


def _extract_in_chunks(
    path: Path,
    by_action: dict[str, list[int]],
    settings: ExtractionSettings,
    progress: bool,
    parallel_map: ParallelMap,
) -> dict[str, dict[str, np.ndarray]]:
    tasks = [
        (str(path), name, rows[i : i + _CHUNK_ROWS], settings)
        for name, rows in by_action.items()
        for i in range(0, len(rows), _CHUNK_ROWS)
    ]
    parts: list[dict[str, np.ndarray] | None] = [None] * len(tasks)
    total = sum(len(v) for v in by_action.values())
    bar = Progress(total, "recording", f"features {path.name}") if progress else None
    try:
        for i, part in parallel_map(_extract_chunk, tasks):
            parts[i] = part
            if bar is not None:
                bar.update(len(tasks[i][2]))
    finally:
        if bar is not None:
            bar.close()
    values: dict[str, dict[str, np.ndarray]] = {}
    for name in by_action:
        mine = [p for (_, n, _, _), p in zip(tasks, parts) if n == name and p is not None]
        if len(mine) != sum(1 for t in tasks if t[1] == name):
            raise InvalidStateError(f"features of {name}: a parallel task returned no result")
        values[name] = {m: np.concatenate([p[m] for p in mine]) for m in mine[0]}
    return values


def load_observations(
    path: str | Path,
    *,
    actions: Sequence[str] | None = None,
    objects: Iterable[str] | None = None,
    trials: Iterable[int] | None = None,
    settings: ExtractionSettings | None = None,
    extract_missing: bool = True,
    progress: bool = False,
) -> dict[str, Observations]:
    """Observation table from a data set, optionally restricted to objects and trial numbers.

    Stored features are used when they were extracted with ``settings``; the others are
    extracted in memory (``extract_missing=False``: a ``DatasetError`` instead). The file is only
    read: run :func:`extract_features` (``aptkt dataset features``) to store them.
    """
    path = Path(path)
    settings = settings or ExtractionSettings()
    key = settings.to_dict()
    obj_filter = None if objects is None else {str(o) for o in objects}
    trial_filter = None if trials is None else {int(t) for t in trials}
    table: dict[str, Observations] = {}
    with DatasetReader(path) as rd:
        keys = rd.keys()
        recorded = sorted({k[1] for k in keys})
        recorded_objects = {k[0] for k in keys}
        names = list(actions) if actions is not None else recorded
        unknown = [a for a in names if a not in recorded]
        if unknown:
            raise DatasetError(
                f"{path} holds no recordings of action(s) {', '.join(unknown)}; "
                f"it has {', '.join(recorded)}"
            )
        if obj_filter is not None and obj_filter - recorded_objects:
            raise DatasetError(
                f"{path} holds no recordings of object(s) "
                f"{', '.join(sorted(obj_filter - recorded_objects))}; "
                f"it has {', '.join(sorted(recorded_objects))}"
            )
        todo = [a for a in names if not _features_current(rd, a, key)]
        if todo and not extract_missing:
            raise DatasetError(
                f"{path} has no features stored with these extraction settings for every "
                f"recording of {todo}; run `aptkt dataset features`"
            )

        def wanted(i: int) -> bool:
            obj, _, trial = keys[i]
            return (obj_filter is None or obj in obj_filter) and (
                trial_filter is None or trial in trial_filter
            )

        # Only the recordings asked for are extracted in memory (one if none is: the table
        # still needs each modality's width).
        by_action = {
            name: [i for i in rows if wanted(i)] or rows[:1]
            for name, rows in (_rows_by_action(rd, todo) if todo else {}).items()
        }
        fresh = _extract(rd, by_action, settings, progress, f"features {path.name}")
        for name in names:
            mods: dict[str, Any] = {}
            if name in todo:
                recs = np.asarray(by_action[name], dtype=np.int64)
                mods = dict(fresh[name])
            else:
                for modality in rd.feature_names()[name]:
                    recs, mods[modality] = rd.features(name, modality)
            keep = np.array([wanted(int(i)) for i in recs], dtype=bool)
            objs = np.array([keys[i][0] for i in recs])
            trs = np.array([keys[i][2] for i in recs], dtype=np.int64)
            table[name] = Observations(
                name, {m: v[keep] for m, v in mods.items()}, objs[keep], trs[keep], SKIN_EXTRACTION
            )
    return table
