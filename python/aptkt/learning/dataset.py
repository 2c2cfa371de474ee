"""Feature observations from recorded data sets (HDF5, :mod:`aptkt.data`).

:func:`extract_features` computes every recording's feature observation once and stores it in
the file (``/features/<action>/<modality>``); :func:`load_observations` reads them back as an
observation table, extracting first if needed.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.actions import ExploratoryAction
from aptkt.data import DatasetError, DatasetReader, store_features
from aptkt.learning.extract import ExtractionSettings, observe_recording
from aptkt.learning.observations import Observations

__all__ = ["extract_features", "load_observations", "stored_actions"]


def stored_actions(path: str | Path) -> dict[str, ExploratoryAction]:
    """The actions recorded in a data set, with their parameters as recorded."""
    actions: dict[str, ExploratoryAction] = {}
    with DatasetReader(path) as rd:
        for i in range(len(rd)):
            _, name, _ = rd.key(i)
            if name not in actions:
                actions[name] = ExploratoryAction.from_dict(rd.metadata(i)["action"])
    return actions


def extract_features(
    path: str | Path,
    *,
    actions: Iterable[str] | None = None,
    settings: ExtractionSettings | None = None,
    progress: bool = True,
) -> dict[str, int]:
    """Extract and store the feature observations of every recording (of ``actions``).

    Returns the number of recordings per action. The file must not be open for writing.
    """
    path = Path(path)
    wanted = None if actions is None else set(actions)
    by_action: dict[str, list[int]] = {}
    with DatasetReader(path) as rd:
        recorded = set()
        for i in range(len(rd)):
            _, name, _ = rd.key(i)
            recorded.add(name)
            if wanted is None or name in wanted:
                by_action.setdefault(name, []).append(i)
        missing = (wanted or set()) - recorded
        if missing:
            raise DatasetError(
                f"{path} holds no recordings of action(s) {', '.join(sorted(missing))}; "
                f"it has {', '.join(sorted(recorded))}"
            )
        total = sum(len(v) for v in by_action.values())
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="rec", desc=f"features {path.name}")
        values: dict[str, dict[str, list[np.ndarray]]] = {}
        try:
            for name, rows in by_action.items():
                action = ExploratoryAction.from_dict(rd.metadata(rows[0])["action"])
                per_mod: dict[str, list[np.ndarray]] = {m: [] for m in action.modalities}
                for i in rows:
                    try:
                        rec = rd.recording(i)
                    except (OSError, ValueError) as exc:
                        obj, _, trial = rd.key(i)
                        raise DatasetError(
                            f"{path}: recording {i} ({obj}/{name}/trial {trial}) is damaged "
                            f"({exc}); 'aptkt dataset repair {path}' keeps the readable ones"
                        ) from None
                    obs = observe_recording(rec, action, settings)
                    for m, v in obs.items():
                        per_mod[m].append(v)
                    if bar is not None:
                        bar.update(1)
                values[name] = per_mod
        finally:
            if bar is not None:
                bar.close()
    store_features(
        path,
        {
            name: (by_action[name], {m: np.stack(rows) for m, rows in per_mod.items()})
            for name, per_mod in values.items()
        },
    )
    return {name: len(rows) for name, rows in by_action.items()}


def load_observations(
    path: str | Path,
    *,
    actions: Sequence[str] | None = None,
    objects: Iterable[str] | None = None,
    trials: Iterable[int] | None = None,
    extract_missing: bool = True,
    progress: bool = False,
) -> dict[str, Observations]:
    """Observation table from a data set, optionally restricted to objects and trial numbers."""
    path = Path(path)
    with DatasetReader(path) as rd:
        stored = rd.feature_names()
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
    if objects is not None:
        objects = list(objects)
        unknown = sorted({str(o) for o in objects} - recorded_objects)
        if unknown:
            raise DatasetError(
                f"{path} holds no recordings of object(s) {', '.join(unknown)}; "
                f"it has {', '.join(sorted(recorded_objects))}"
            )
    todo = [a for a in names if a not in stored]
    if todo:
        if not extract_missing:
            raise DatasetError(
                f"{path} has no stored features for {todo}; run `aptkt dataset features`"
            )
        extract_features(path, actions=todo, progress=progress)
    obj_filter = None if objects is None else {str(o) for o in objects}
    trial_filter = None if trials is None else {int(t) for t in trials}
    table: dict[str, Observations] = {}
    with DatasetReader(path) as rd:
        keys = rd.keys()
        for name in names:
            mods: dict[str, Any] = {}
            recs = None
            for modality in rd.feature_names()[name]:
                recs, vals = rd.features(name, modality)
                mods[modality] = vals
            assert recs is not None
            objs = np.array([keys[i][0] for i in recs])
            trs = np.array([keys[i][2] for i in recs], dtype=np.int64)
            keep = np.ones(len(recs), dtype=bool)
            if obj_filter is not None:
                keep &= np.isin(objs, list(obj_filter))
            if trial_filter is not None:
                keep &= np.isin(trs, list(trial_filter))
            table[name] = Observations(
                name, {m: v[keep] for m, v in mods.items()}, objs[keep], trs[keep]
            )
    return table
