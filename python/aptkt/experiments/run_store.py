"""Finished runs on disk, so an interrupted experiment resumes where it stopped.

Each finished run's step rows are written to ``<directory>/<key>.json`` the moment the run
completes (to a temporary name first, then renamed: a file under its real name is always
complete). The key is a hash of everything that determines the run's result — the learner's
configuration, the actions, objects and trials, the pool seed, the prior knowledge's content
key and the data set's content (:func:`data_fingerprint`) — and of nothing else: labels
(method name, tags) and file locations do not enter it, so a run shared by two figures is
computed once and a moved output directory keeps its results.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Iterable
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.data import DatasetReader
from aptkt.errors import ConfigError
from aptkt.experiments.runs import RunSpec
from aptkt.files import open_atomically, strict_json

__all__ = ["RunStore", "data_fingerprint", "run_key", "canonical_json"]

_FORMAT = "aptkt.RunResult/1"


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no whitespace: equal values give equal text."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=str)


def _digest(value: Any) -> str:
    return hashlib.sha256(canonical_json(value).encode()).hexdigest()


@lru_cache(maxsize=16)
def _fingerprint(path: str, size: int, mtime_ns: int) -> str:
    h = hashlib.sha256()
    with DatasetReader(path) as rd:
        h.update(canonical_json(rd.keys()).encode())
        for action, modalities in sorted(rd.feature_names().items()):
            for modality in sorted(modalities):
                recs, values = rd.features(action, modality)
                h.update(f"{action}/{modality}".encode())
                h.update(np.ascontiguousarray(recs, dtype=np.int64).tobytes())
                h.update(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return h.hexdigest()[:16]


def data_fingerprint(path: str | Path) -> str:
    """Content hash of a data set as the learner sees it: its recordings' keys (object, action,
    trial) and every stored feature observation. Extract features before calling this."""
    st = os.stat(path)
    return _fingerprint(str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def run_key(spec: RunSpec, fingerprint: str) -> str:
    """The hash naming a run's result (see the module docstring for what enters it)."""
    content = {
        "version": __version__,
        "data": fingerprint,
        "config": spec.config.to_dict(),
        "actions": list(spec.actions),
        "new_objects": list(spec.new_objects),
        "pool_trials": list(spec.pool_trials),
        "test_trials": list(spec.test_trials),
        "pool_seed": spec.pool_seed,
        # Prior files are content-addressed (aptkt.experiments.priors): the name is the content.
        "prior": None if spec.prior is None else Path(spec.prior).name,
    }
    return _digest(content)[:24]


_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


class RunStore:
    """A directory of finished runs, one JSON file per run key."""

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.json"

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and self.path(key).exists()

    def load(self, key: str) -> list[dict[str, Any]] | None:
        """The stored step rows of a run, or None if it has not finished (or its file is not a
        run result, which is then ignored and recomputed)."""
        p = self.path(key)
        try:
            doc = json.loads(p.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return None
        if not isinstance(doc, dict) or doc.get("format") != _FORMAT or doc.get("key") != key:
            return None
        steps = doc.get("steps")
        if not isinstance(steps, list):
            return None
        # The cells strict JSON holds as null, back as the non-finite numbers they were.
        for cell in doc.get("non_finite", []):
            try:
                i, name, text = cell
                # (One object per constant, as json's own NaN: two loads of a run compare equal.)
                steps[i][name] = _NON_FINITE[text]
            except (TypeError, ValueError, IndexError, KeyError):
                return None
        return steps

    def save(self, key: str, spec: RunSpec, steps: Iterable[dict[str, Any]]) -> Path:
        rows = list(steps)
        # Strict JSON, which every reader takes, has no NaN (an uncertainty where nothing was
        # chosen, a mean λ without a transfer): such a cell is null, and named here so that a
        # resumed run gets back exactly the number it stored.
        non_finite = [
            [i, name, repr(float(v))]
            for i, row in enumerate(rows)
            for name, v in row.items()
            if isinstance(v, (float, np.floating)) and not math.isfinite(v)
        ]
        doc = {
            "format": _FORMAT,
            "key": key,
            "software_version": __version__,
            "spec": spec.to_dict(),
            "steps": rows,
            "non_finite": non_finite,
        }
        final = self.path(key)
        text = strict_json(doc, indent=None)
        # (The temporary name is unique per write: workers on several hosts, or a retried task,
        # may save the same run at once; each renames its own complete file.)
        with open_atomically(final, ConfigError) as fh:
            fh.write(text)
        return final

    def keys(self) -> list[str]:
        return sorted(p.stem for p in self.directory.glob("*.json"))
