"""Saving and loading fitted models without pickle: the training arrays, the fitted
hyper-parameters and JSON metadata in a NumPy ``.npz`` file; loading refits at those
hyper-parameters without optimising, which rebuilds the model exactly."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.gp.settings import DEFAULTS, HyperPrior
from aptkt.gp.sources import TransferSource

__all__ = ["from_state", "load", "save", "state"]

#: Parameters a saved model leaves out at their default (added after the format was fixed).
_OMITTED_AT_DEFAULT = ("class_prior", "latent_mean", "optimizer_tol", "kernel", "tie_length_scales")
_SAVE_FORMAT = "aptkt.LaplaceGPC/2"
#: Formats :func:`from_state` still reads (version 1: one positives-only source per class, no
#: hyper-prior).
_OLD_FORMATS = ("aptkt.LaplaceGPC/1",)


def state(gpc: Any) -> dict[str, np.ndarray]:
    """Arrays and JSON metadata that rebuild a fitted LaplaceGPC exactly (see :func:`from_state`)."""
    source_meta = []
    arrays = {
        "X": gpc.X_train_,
        "y": np.searchsorted(gpc.classes_, gpc.y_train_).astype(np.int64),
        "theta": gpc.theta_,
    }
    i = 0
    for label, lst in gpc.sources_.items():
        for src in lst:
            source_meta.append(
                {
                    "class": _jsonable(label),
                    "name": src.name,
                    "transfer_lambda": src.transfer_lambda,
                    "labelled": src.y is not None,
                }
            )
            arrays[f"source_X_{i}"] = src.X
            if src.y is not None:
                arrays[f"source_y_{i}"] = src.y
            i += 1
    meta = {
        "format": _SAVE_FORMAT,
        "params": {
            k: _jsonable(v)
            for k, v in gpc.get_params().items()
            # class_prior, latent_mean and optimizer_tol at their defaults are left out:
            # files stay readable by the versions before them, which share this format (and
            # the prior files' keys).
            if k != "random_state" and not (k in _OMITTED_AT_DEFAULT and v == getattr(DEFAULTS, k))
        },
        "classes": gpc.classes_.tolist(),
        "sources": source_meta,
    }
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return arrays


def from_state(cls: Any, arrays: Mapping[str, np.ndarray]) -> Any:
    """Rebuild a model from :meth:`state`'s arrays (this format or version 1)."""
    meta = json.loads(bytes(np.asarray(arrays["meta"], dtype=np.uint8)).decode())
    fmt = meta.get("format")
    if fmt != _SAVE_FORMAT and fmt not in _OLD_FORMATS:
        raise ValueError(f"not a saved LaplaceGPC (format {fmt!r})")
    params = dict(meta["params"])
    params["fixed"] = tuple(params["fixed"])
    for key in ("length_scale_bounds", "signal_variance_bounds"):
        params[key] = tuple(params[key])
    if isinstance(params.get("hyper_prior"), Mapping):
        # Files written before the modality-weight prior existed had flat weights.
        params["hyper_prior"] = HyperPrior(**{"modality_weight_sd": None, **params["hyper_prior"]})
    model = cls(**params)
    classes = np.asarray(meta["classes"])
    y = classes[np.asarray(arrays["y"])]
    sources: dict[Any, list[TransferSource]] = {}
    if fmt == "aptkt.LaplaceGPC/1":  # one positives-only source per class
        for i, label in enumerate(meta["source_classes"]):
            lam = float(arrays[f"source_lambda_{i}"])
            sources[label] = [TransferSource(np.asarray(arrays[f"source_X_{i}"]), None, lam)]
    else:
        for i, entry in enumerate(meta["sources"]):
            src = TransferSource(
                np.asarray(arrays[f"source_X_{i}"]),
                np.asarray(arrays[f"source_y_{i}"]) if entry["labelled"] else None,
                entry["transfer_lambda"],
                name=entry["name"],
            )
            sources.setdefault(entry["class"], []).append(src)
    return model._fit(np.asarray(arrays["X"]), y, sources, thetas=np.asarray(arrays["theta"]))


def save(gpc: Any, path: str | Path) -> None:
    """Save to a ``.npz`` file (arrays + JSON; loading executes no code)."""
    arrays: dict[str, Any] = gpc.state()
    np.savez_compressed(Path(path), **arrays)


def load(cls: Any, path: str | Path) -> Any:
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: not a saved LaplaceGPC (not an .npz archive)")
    with np.load(Path(path), allow_pickle=False) as data:
        return cls.from_state({k: data[k] for k in data.files})


def _jsonable(value: Any) -> Any:
    if isinstance(value, HyperPrior):
        return asdict(value)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [_jsonable(v) for v in value]
    if isinstance(value, range):
        return list(value)
    return value
