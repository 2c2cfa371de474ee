"""Features stored in a data set beside its recordings: per action and modality, one row per
recording number, keyed by the extraction settings they were computed with. A cache: the file
is never changed in place, the features are written into a copy that replaces it."""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from aptkt.data.hdf5 import cut_short, writer_mark
from aptkt.data.lock import WriterLock
from aptkt.data.schema import check_schema
from aptkt.errors import DatasetError, InvalidInputError
from aptkt.files import replaced_atomically

__all__ = ["store_features", "write_features"]


def write_features(
    path: str | Path,
    action: str,
    modality: str,
    recordings: Sequence[int],
    values: np.ndarray,
    *,
    settings: Mapping[str, Any] | None = None,
) -> None:
    """Store a feature matrix (one row per recording number) under ``/features/<action>``
    (see :func:`store_features`)."""
    store_features(path, {action: (recordings, {modality: values})}, settings=settings)


def store_features(
    path: str | Path,
    features: Mapping[str, tuple[Sequence[int], Mapping[str, np.ndarray]]],
    *,
    settings: Mapping[str, Any] | None = None,
) -> None:
    """Store feature matrices: ``{action: (recording numbers, {modality: values})}``, keyed by
    the extraction ``settings`` they were computed with (JSON, see
    :meth:`DatasetReader.feature_settings`; None: unknown settings).

    The file is never modified in place: the features are written into a copy that then
    replaces it (a rename), so a kill at any moment leaves the file as it was, or with all the
    features. No writer may be running (the copy would miss its later appends): the data
    set's lock is held meanwhile (:mod:`aptkt.data.lock`)."""
    path = Path(path)
    checked = {}
    for action, (recordings, mods) in features.items():
        recs = np.asarray(recordings, dtype=np.int64)
        vals = {m: np.asarray(v, dtype=np.float64) for m, v in mods.items()}
        for v in vals.values():
            if v.ndim != 2 or v.shape[0] != recs.shape[0]:
                raise InvalidInputError(
                    "values must be (n_recordings, dim) with one row per recording number"
                )
        checked[action] = (recs, vals)
    with WriterLock.acquire(path):
        _store(path, checked, settings)


def _store(
    path: Path,
    checked: Mapping[str, tuple[np.ndarray, Mapping[str, np.ndarray]]],
    settings: Mapping[str, Any] | None,
) -> None:
    if writer_mark(path):
        raise DatasetError(
            f"{path}: a writer has the file open, or died without closing it; wait for it to "
            f"finish, or run 'aptkt dataset repair {path}' first"
        )
    if cut_short(path):
        raise DatasetError(
            f"{path}: the file is cut short (it ends before the end HDF5 recorded in it): "
            f"features cannot be stored in it; run 'aptkt dataset repair {path}' first (it "
            "keeps every readable recording)"
        )
    with replaced_atomically(path, DatasetError, temp_suffix=".features-tmp") as tmp:
        shutil.copyfile(path, tmp)
        with h5py.File(tmp, "a", libver="latest") as f:
            check_schema(f, path)
            n = f["recordings/index"].shape[0]
            for action, (recs, vals) in checked.items():
                if recs.size and (recs.min() < 0 or recs.max() >= n):
                    raise InvalidInputError(f"recording numbers must be in 0..{n - 1}")
                g = f.require_group(f"features/{action}")
                if "recording" in g and not np.array_equal(g["recording"][...], recs):
                    if not set(vals) >= set(g) - {"recording"}:
                        raise InvalidInputError(
                            f"features of {action!r} exist for other recordings; write all "
                            "modalities together"
                        )
                    del g["recording"]
                    for m in [k for k in g if k != "recording"]:
                        del g[m]
                # Fletcher-32: a changed byte is an error when read, not another number.
                if "recording" not in g:
                    g.create_dataset("recording", data=recs, track_times=False, fletcher32=True)
                for modality, values in vals.items():
                    if modality in g:
                        del g[modality]
                    g.create_dataset(modality, data=values, track_times=False, fletcher32=True)
                if settings is None:
                    g.attrs.pop("extraction", None)
                else:
                    g.attrs["extraction"] = json.dumps(dict(settings), sort_keys=True)
