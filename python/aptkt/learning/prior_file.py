"""Reading a prior-knowledge ``.npz`` file defensively.

A prior file comes from elsewhere (another machine, another version, a colleague's mail), and
``aptkt learn`` acts on it only after the robot has moved: so every member is checked before
anything is built from it, and nothing the file declares is trusted with memory.

* Only the members the format defines are read (see :func:`expected_member`); any other
  member is an error, and is never decompressed.
* Each member's header (dtype, shape) is read first; its declared size is checked against
  :data:`PRIOR_FILE_MAX_BYTES` (for all members together) before its data is read.
* Object arrays, pickles and non-native types are refused (``allow_pickle=False``).
* Names, dtypes, shapes and their consistency (observations ↔ pipeline ↔ model) are checked;
  a failure is a :class:`~aptkt.errors.PriorFileError` naming the member.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import PriorFileError
from aptkt.features import MAX_MAGNITUDE
from aptkt.files import NPZ_MAX_BYTES, json_member, read_npz
from aptkt.names import name_problem

__all__ = ["FORMAT", "PRIOR_FILE_MAX_BYTES", "check_action", "check_calibration", "read_members"]

FORMAT = "aptkt.PriorKnowledge/1"

#: Largest total (uncompressed) size of the arrays of a prior file (that of every ``.npz``
#: file aptkt reads, :data:`aptkt.files.NPZ_MAX_BYTES`).
PRIOR_FILE_MAX_BYTES = NPZ_MAX_BYTES

_META_MAX_BYTES = 1 << 20
_NAME = r"[A-Za-z0-9_.\-]+"
_MEMBER_PATTERNS = [
    re.compile(p)
    for p in (
        r"meta",
        r"a\d+/obs/(objects|trials)",
        rf"a\d+/obs/modality/{_NAME}",
        r"a\d+/pipeline/(modalities|joint)",
        rf"a\d+/pipeline/{_NAME}/(log_columns|pca_components|mean|scale|pca_scale|components)",
        r"a\d+/model/(meta|X|y|theta)",
        r"a\d+/model/source_(X|lambda)_\d+",
        r"a\d+/(sample|impostors)",
        r"calibration/(held_in|held_out)",
    )
]


def expected_member(name: str) -> bool:
    return any(p.fullmatch(name) for p in _MEMBER_PATTERNS)


def read_members(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The file's metadata (checked) and its arrays, each member checked before it is read
    (:func:`aptkt.files.read_npz`)."""
    arrays = read_npz(
        path,
        known=expected_member,
        error=PriorFileError,
        kind="prior-knowledge file",
        max_bytes=PRIOR_FILE_MAX_BYTES,
        member_max_bytes={"meta": _META_MAX_BYTES},
    )
    meta = _meta(arrays.pop("meta"), path)
    return meta, arrays


def _meta(raw: np.ndarray, path: Path) -> dict[str, Any]:
    meta = json_member(raw, path, "meta", PriorFileError)
    if meta.get("format") != FORMAT:
        raise PriorFileError(
            f"{path}: unsupported format {meta.get('format')!r} (expected {FORMAT})"
        )
    actions = meta.get("actions")
    if (
        not isinstance(actions, list)
        or not actions
        or not all(isinstance(a, str) and a for a in actions)
    ):
        raise PriorFileError(
            f"{path}: member 'meta': 'actions' must be a non-empty list of action names, "
            f"got {actions!r}"
        )
    if len(set(actions)) != len(actions):
        raise PriorFileError(f"{path}: member 'meta': an action appears twice in {actions}")
    touches = meta.get("calibration_touches")
    if touches is not None and (
        not isinstance(touches, int) or isinstance(touches, bool) or touches < 1
    ):
        raise PriorFileError(
            f"{path}: member 'meta': 'calibration_touches' must be a positive integer, "
            f"got {touches!r}"
        )
    if not isinstance(meta.get("metadata", {}), dict):
        raise PriorFileError(f"{path}: member 'meta': 'metadata' must be a JSON object")
    _check_metadata(meta.get("metadata", {}), path)
    joint = meta.get("joint")
    if joint is not None and (not _is_names(joint) or not set(joint) <= set(actions)):
        raise PriorFileError(
            f"{path}: member 'meta': 'joint' must list actions of the file, got {joint!r}"
        )
    extractions = meta.get("extractions", {})
    if (
        not isinstance(extractions, dict)
        or not set(extractions) <= set(actions)
        or not all(isinstance(v, str) and v for v in extractions.values())
    ):
        raise PriorFileError(
            f"{path}: member 'meta': 'extractions' must map actions of the file to names, "
            f"got {extractions!r}"
        )
    return meta


def _is_names(value: Any) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


def _is_map(value: Any, of: Callable[[Any], bool]) -> bool:
    return isinstance(value, dict) and all(of(v) for v in value.values())


def _is_provenance(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(p, dict)
        and isinstance(p.get("source"), str)
        and _is_names(p.get("objects"))
        and (
            "trials" not in p
            or _is_map(p["trials"], lambda t: _is_map(t, lambda v: isinstance(v, list)))
        )
        for p in value
    )


def _is_definition(name: str, value: Any) -> bool:
    """An exploratory action's definition, as ``ExploratoryAction.to_dict`` writes it, under
    its own name: a live run compares its actions with these before the robot moves."""
    from aptkt.actions import ExploratoryAction

    if not isinstance(value, dict) or value.get("name", name) != name:
        return False
    try:
        ExploratoryAction.from_dict(value)
    except (TypeError, ValueError):
        return False
    return True


#: What the metadata entries other code reads must be (the rest is shown, never used): the
#: check each must pass and what it says when it does not.
_METADATA_SHAPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "provenance": (
        _is_provenance,
        "a list of JSON objects, each with a 'source' name and a list of 'objects'",
    ),
    "merged_from": (_is_names, "a list of file names"),
    "action_definitions": (
        lambda v: isinstance(v, dict) and all(_is_definition(k, d) for k, d in v.items()),
        "a JSON object of action names to their definitions (aptkt.actions)",
    ),
    "feature_table_columns": (
        lambda v: _is_map(v, lambda m: _is_map(m, _is_names)),
        "a JSON object of actions to modalities to lists of column names",
    ),
}


def _check_metadata(metadata: dict[str, Any], path: Path) -> None:
    """The metadata other code reads is of the shape it reads (a forged or damaged entry is
    refused here, naming it, not met as a traceback in ``prior merge``)."""
    for key, (fits, shape) in _METADATA_SHAPES.items():
        if key in metadata and not fits(metadata[key]):
            raise PriorFileError(
                f"{path}: member 'meta': metadata {key!r} must be {shape}, got "
                f"{_shortened(metadata[key])}"
            )


def _shortened(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Checker:
    """Checks of one action's members; every failure names the member."""

    def __init__(self, path: Path, arrays: dict[str, np.ndarray], prefix: str, action: str):
        self.path, self.arrays, self.prefix, self.action = path, arrays, prefix, action

    def fail(self, member: str, problem: str) -> PriorFileError:
        return PriorFileError(
            f"{self.path}: member {self.prefix}/{member!s} (action {self.action}): {problem}"
        )

    def get(
        self,
        member: str,
        kinds: str,
        ndim: int,
        shape: Callable[[tuple[int, ...]], bool] | None = None,
        want: str = "",
        allowed: tuple[float, ...] = (),
    ) -> np.ndarray:
        key = f"{self.prefix}/{member}"
        if key not in self.arrays:
            raise self.fail(member, "missing")
        a = self.arrays[key]
        if a.dtype.kind not in kinds:
            names = {"U": "text", "i": "integer", "u": "integer", "f": "float", "b": "boolean"}
            expected = " or ".join(sorted({names[k] for k in kinds}))
            raise self.fail(member, f"expected {expected} values, got {a.dtype}")
        if a.ndim != ndim or (shape is not None and not shape(a.shape)):
            raise self.fail(member, f"expected a {ndim}-D array{want}, got shape {a.shape}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a) | np.isin(a, allowed)):
            raise self.fail(member, "non-finite values")
        return a


def check_action(path: Path, arrays: dict[str, np.ndarray], prefix: str, action: str) -> None:
    """Names, dtypes, shapes and consistency of one action's observations, pipeline and model."""
    c = _Checker(path, arrays, prefix, action)
    objects = c.get("obs/objects", "U", 1)
    n = objects.shape[0]
    if n == 0:
        raise c.fail("obs/objects", "no observations")
    if any(not str(o) for o in objects):
        raise c.fail("obs/objects", "an empty object name")
    for name in dict.fromkeys(objects.tolist()):
        why = name_problem(str(name))
        if why is not None:
            raise c.fail("obs/objects", why)
    c.get("obs/trials", "iu", 1, lambda s: s == (n,), f" of {n} trial numbers")
    mod_prefix = f"{prefix}/obs/modality/"
    obs_mods = sorted(k[len(mod_prefix) :] for k in arrays if k.startswith(mod_prefix))
    if not obs_mods:
        raise c.fail("obs/modality", "no modality")
    dims = {}
    for m in obs_mods:
        a = c.get(f"obs/modality/{m}", "f", 2, lambda s: s[0] == n, f" with {n} rows")
        largest = float(np.max(np.abs(a))) if a.size else 0.0
        if largest > MAX_MAGNITUDE:
            # As a table's: refitting the library (a merge) would square them into infinity.
            raise c.fail(
                f"obs/modality/{m}",
                f"a value of {largest:g} is beyond ±{MAX_MAGNITUDE:g}; no sensor's feature is "
                "that large",
            )
        dims[m] = a.shape[1]
    pipe_mods = c.get("pipeline/modalities", "U", 1).tolist()
    if sorted(pipe_mods) != obs_mods or len(set(pipe_mods)) != len(pipe_mods):
        raise c.fail("pipeline/modalities", f"{pipe_mods} differ from the observations' {obs_mods}")
    width = 0
    for m in pipe_mods:
        d = dims[m]
        logs = c.get(f"pipeline/{m}/log_columns", "iu", 1)
        if logs.size and not (0 <= logs.min() and logs.max() < d):
            raise c.fail(f"pipeline/{m}/log_columns", f"columns outside 0..{d - 1}")
        pca = int(c.get(f"pipeline/{m}/pca_components", "iu", 0))
        c.get(f"pipeline/{m}/mean", "f", 1, _vector_of(d), f" of {d} values")
        scale = c.get(f"pipeline/{m}/scale", "f", 1, _vector_of(d), f" of {d} values")
        if np.any(scale <= 0):
            raise c.fail(f"pipeline/{m}/scale", "scales must be > 0")
        if float(c.get(f"pipeline/{m}/pca_scale", "f", 0)) <= 0:
            raise c.fail(f"pipeline/{m}/pca_scale", "must be > 0")
        if f"{prefix}/pipeline/{m}/components" in arrays:
            comp = c.get(
                f"pipeline/{m}/components",
                "f",
                2,
                _rows_of_width(d),
                f" of shape (k, {d})",
            )
            # Without a PCA the components are the noise whitening: a map of all the columns.
            if pca < 0 and comp.shape[0] != d:
                raise c.fail(f"pipeline/{m}/components", f"a whitening map needs {d} rows (no PCA)")
            width += comp.shape[0]
        else:
            if pca >= 0:
                raise c.fail(f"pipeline/{m}/components", "missing (pca_components is set)")
            width += d
    if f"{prefix}/pipeline/joint" in arrays:
        # The noise whitening across modalities: a map of the modalities' outputs side by side.
        c.get(
            "pipeline/joint", "f", 2, lambda s: s == (width, width), f" of shape ({width}, {width})"
        )
    if len(set(objects.tolist())) < 2:
        raise c.fail("obs/objects", "prior knowledge needs at least two objects")
    # The model's rows: every observation, or the sample its kernel was learned on.
    fitted = objects
    if f"{prefix}/sample" in arrays:
        sample = c.get("sample", "iu", 1)
        if sample.size < 2 or np.any(np.diff(sample) <= 0) or sample[0] < 0 or sample[-1] >= n:
            raise c.fail("sample", f"expected increasing row numbers within 0..{n - 1}")
        fitted = objects[sample]
    m = fitted.shape[0]
    X = c.get("model/X", "f", 2, lambda s: s == (m, width), f" of shape ({m}, {width})")
    del X
    y = c.get("model/y", "iu", 1, lambda s: s == (m,), f" of {m} class numbers")
    classes = sorted(set(fitted.tolist()))
    if len(classes) < 2:
        raise c.fail("sample", "the model needs at least two objects")
    if y.min() < 0 or y.max() >= len(classes) or [classes[i] for i in y] != fitted.tolist():
        raise c.fail("model/y", "the model's training labels differ from the observations' objects")
    if f"{prefix}/impostors" in arrays:
        most = int(np.unique(objects, return_counts=True)[1].max())
        c.get(
            "impostors",
            "f",
            1,
            lambda s: s == (most + 1,),
            f" of {most + 1} values (one per number of observations up to {most})",
            allowed=(-np.inf,),
        )
    meta_raw = c.get("model/meta", "u", 1)
    try:
        meta = json.loads(meta_raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise c.fail("model/meta", f"not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("classes") != classes:
        got = meta.get("classes") if isinstance(meta, dict) else meta
        raise c.fail("model/meta", f"classes {got!r} differ from the observations' {classes}")
    theta = c.get("model/theta", "f", 2)
    rows = 1 if len(classes) == 2 else len(classes)  # two classes: a single binary classifier
    if theta.shape[0] != rows:
        raise c.fail("model/theta", f"expected {rows} row(s) of hyper-parameters")


def check_calibration(path: Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """The calibration scores of recognition, if the file has them: both members and the
    number of touches, novelty values (+inf where no known object could have given a touch)."""
    present = [k for k in ("calibration/held_in", "calibration/held_out") if k in arrays]
    if not present and "calibration_touches" not in meta:
        return
    for key in ("calibration/held_in", "calibration/held_out"):
        if key not in arrays:
            raise PriorFileError(f"{path}: member {key}: missing (the calibration is incomplete)")
        a = arrays[key]
        if a.dtype.kind != "f" or a.ndim != 1:
            raise PriorFileError(
                f"{path}: member {key}: expected a 1-D float array, got {a.dtype} {a.shape}"
            )
        if np.any(np.isnan(a) | (a == -np.inf)):
            raise PriorFileError(f"{path}: member {key}: NaN or -inf values")
    touches = meta.get("calibration_touches")
    held_in = arrays["calibration/held_in"]
    if touches is None or held_in.size == 0 or held_in.size > touches:
        raise PriorFileError(
            f"{path}: member calibration/held_in: {held_in.size} scores of "
            f"{touches!r} touches (meta 'calibration_touches')"
        )


def _vector_of(d: int) -> Callable[[tuple[int, ...]], bool]:
    """Shape check: a vector of ``d`` values."""
    return lambda shape: shape == (d,)


def _rows_of_width(d: int) -> Callable[[tuple[int, ...]], bool]:
    """Shape check: 1 to ``d`` rows of ``d`` values (PCA components, or the whitening)."""
    return lambda shape: shape[1] == d and 1 <= shape[0] <= d
