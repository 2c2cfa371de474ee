"""Saving and loading fitted models without pickle: the training arrays, the fitted
hyper-parameters and JSON metadata in a NumPy ``.npz`` file; loading refits at those
hyper-parameters without optimising, which rebuilds the model exactly.

A model file is read as a prior file is (:func:`aptkt.files.read_npz`): only its own members,
their declared sizes within :data:`aptkt.files.NPZ_MAX_BYTES` before anything is
decompressed; then every member is checked against the metadata before the model is rebuilt.
Every problem is a :class:`~aptkt.errors.ModelFileError` naming the file and the member.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ModelFileError, ProblemTooLargeError
from aptkt.files import json_member, open_atomically, read_npz
from aptkt.gp.settings import DEFAULTS, HyperPrior
from aptkt.gp.sources import TransferSource

__all__ = ["from_state", "load", "save", "state"]

#: Parameters a saved model leaves out at their default (added after the format was fixed).
_OMITTED_AT_DEFAULT = ("class_prior", "latent_mean", "optimizer_tol", "kernel", "tie_length_scales")
_SAVE_FORMAT = "aptkt.LaplaceGPC/2"
#: Formats :func:`from_state` still reads (version 1: one positives-only source per class, no
#: hyper-prior).
_OLD_FORMATS = ("aptkt.LaplaceGPC/1",)
#: The members a model file may hold.
_MEMBER = re.compile(r"meta|X|y|theta|source_(X|y|lambda)_\d+")
#: What messages call a state passed from Python rather than read from a file.
_IN_MEMORY = "<state>"


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


def from_state(cls: Any, arrays: Mapping[str, np.ndarray], where: str = _IN_MEMORY) -> Any:
    """Rebuild a model from :meth:`state`'s arrays (this format or version 1). Every member is
    checked first: a problem is a :class:`~aptkt.errors.ModelFileError` naming ``where`` (the
    file) and the member."""
    meta, sources_of = _checked(arrays, where)
    try:
        params = dict(meta["params"])
        params["fixed"] = tuple(params["fixed"])
        for key in ("length_scale_bounds", "signal_variance_bounds"):
            params[key] = tuple(params[key])
        if isinstance(params.get("hyper_prior"), Mapping):
            # Files written before the modality-weight prior existed had flat weights.
            params["hyper_prior"] = HyperPrior(
                **{"modality_weight_sd": None, **params["hyper_prior"]}
            )
        model = cls(**params)
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelFileError(
            f"{where}: member 'meta': its parameters are not a model's ({exc!r})"
        ) from None
    classes = np.asarray(meta["classes"])
    y = classes[np.asarray(arrays["y"])]
    sources: dict[Any, list[TransferSource]] = {}
    try:
        for i, (label, labelled, lam, name) in enumerate(sources_of):
            src = TransferSource(
                np.asarray(arrays[f"source_X_{i}"]),
                np.asarray(arrays[f"source_y_{i}"]) if labelled else None,
                lam,
                name=name,
            )
            sources.setdefault(label, []).append(src)
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{where}: member 'source_X_{i}' or its labels: {exc}") from None
    try:
        return model._fit(np.asarray(arrays["X"]), y, sources, thetas=np.asarray(arrays["theta"]))
    except ProblemTooLargeError as exc:  # (refused before allocating: a model too large here)
        raise ModelFileError(f"{where}: member 'X': the model cannot be rebuilt: {exc}") from None
    except (ValueError, TypeError) as exc:
        raise ModelFileError(
            f"{where}: the members X, y, theta and 'meta' do not make a model ({exc})"
        ) from None


def _checked(
    arrays: Mapping[str, np.ndarray], where: str
) -> tuple[dict[str, Any], list[tuple[Any, bool, float | None, str | None]]]:
    """The metadata and the sources ``(class, labelled, λ, name)`` of a model's members, once
    every member the metadata calls for is there with the type and shape it must have."""

    def fail(member: str, problem: str) -> ModelFileError:
        return ModelFileError(f"{where}: member {member!r}: {problem}")

    def get(member: str, kinds: str, ndim: int) -> np.ndarray:
        if member not in arrays:
            raise fail(member, "missing")
        a = np.asarray(arrays[member])
        if a.dtype.kind not in kinds or a.ndim != ndim:
            raise fail(
                member, f"expected a {ndim}-D array of kind {kinds!r}, got {a.dtype} {a.shape}"
            )
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise fail(member, "non-finite values")
        return a

    meta = json_member(get("meta", "u", 1), where, "meta", ModelFileError)
    fmt = meta.get("format")
    if fmt != _SAVE_FORMAT and fmt not in _OLD_FORMATS:
        raise fail("meta", f"not a saved LaplaceGPC (format {fmt!r})")
    classes = meta.get("classes")
    if not isinstance(meta.get("params"), dict):
        raise fail("meta", "no 'params' object")
    if (
        not isinstance(classes, list)
        or len(classes) < 2
        or len(set(map(repr, classes))) != len(classes)
    ):
        raise fail("meta", f"'classes' must list at least two distinct classes, got {classes!r}")
    X = get("X", "fiu", 2)
    y = get("y", "iu", 1)
    if X.shape[0] == 0 or y.shape != (X.shape[0],):
        raise fail("y", f"expected {X.shape[0]} class numbers (one per row of X), got {y.shape}")
    if y.min() < 0 or y.max() >= len(classes):
        raise fail("y", f"class numbers must lie in 0..{len(classes) - 1}")
    theta = get("theta", "f", 2)
    rows = 1 if len(classes) == 2 else len(classes)  # two classes: a single binary classifier
    if theta.shape[0] != rows:
        raise fail("theta", f"expected {rows} row(s) of hyper-parameters, got {theta.shape[0]}")
    sources: list[tuple[Any, bool, float | None, str | None]] = []
    if fmt == "aptkt.LaplaceGPC/1":  # one positives-only source per class
        listed = meta.get("source_classes", [])
        if not isinstance(listed, list):
            raise fail("meta", "'source_classes' must be a list")
        for i, label in enumerate(listed):
            lam = get(f"source_lambda_{i}", "f", 0)
            sources.append((label, False, float(lam), None))
    else:
        listed = meta.get("sources", [])
        if not isinstance(listed, list) or not all(isinstance(e, dict) for e in listed):
            raise fail("meta", "'sources' must be a list of objects")
        for entry in listed:
            lam = entry.get("transfer_lambda")
            if lam is not None and not isinstance(lam, (int, float)):
                raise fail("meta", f"a source's transfer_lambda must be a number, got {lam!r}")
            sources.append(
                (entry.get("class"), bool(entry.get("labelled")), lam, entry.get("name"))
            )
    for i, (label, labelled, _, _) in enumerate(sources):
        if label not in classes:
            raise fail("meta", f"source {i} names the class {label!r}, which the model has not")
        sx = get(f"source_X_{i}", "fiu", 2)
        if sx.shape[1] != X.shape[1]:
            raise fail(f"source_X_{i}", f"{sx.shape[1]} columns, X has {X.shape[1]}")
        if labelled:
            get(f"source_y_{i}", "biuf", 1)
    extra = sorted(set(arrays) - {"meta", "X", "y", "theta"} - _source_members(fmt, sources))
    if extra:
        raise fail(extra[0], "belongs to no source the metadata lists")
    return meta, sources


def _source_members(fmt: str, sources: list[tuple[Any, bool, Any, Any]]) -> set[str]:
    names = set()
    for i, (_, labelled, _, _) in enumerate(sources):
        names.add(f"source_X_{i}")
        if fmt == "aptkt.LaplaceGPC/1":
            names.add(f"source_lambda_{i}")
        elif labelled:
            names.add(f"source_y_{i}")
    return names


def save(gpc: Any, path: str | Path) -> None:
    """Save to a ``.npz`` file (arrays + JSON; loading executes no code); ``.npz`` is appended
    to a name without it, as NumPy does. The file appears whole or not at all
    (:func:`aptkt.files.replaced_atomically`)."""
    arrays: dict[str, Any] = gpc.state()
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    with open_atomically(path, ModelFileError, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def load(cls: Any, path: str | Path) -> Any:
    """The model saved at ``path``; every member checked before it is read (see the module)."""
    arrays = read_npz(path, known=_known, error=ModelFileError, kind="saved LaplaceGPC")
    return from_state(cls, arrays, str(path))


def _known(member: str) -> bool:
    return _MEMBER.fullmatch(member) is not None


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
