"""A library that grows: prior knowledge merged from several prior-knowledge files — the one a
lab started with and the objects learned since (``aptkt learn`` saves each run's new objects as
a prior file of their own).

Libraries merge only where their observations mean the same: the same actions, each with the
same modalities and feature columns, features extracted with the same settings, the same
metric, the same action definitions, and no object in two of them (a name is an identity: the
same object learned twice would be two objects of one name). The merged observations then
refit everything that depends on them — the metric, the old objects' models, the identity
model — exactly as :meth:`PriorKnowledge.build` does for one library, and the result records
where each object came from.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt import __version__
from aptkt.errors import IncompatiblePriorsError
from aptkt.learning.config import GPSettings
from aptkt.learning.observations import Observations
from aptkt.learning.pipeline import ModalityTransform
from aptkt.learning.prior import PriorKnowledge

__all__ = ["merge_priors", "provenance_of"]


def provenance_of(
    name: str, prior: PriorKnowledge, digest: str | None = None
) -> list[dict[str, Any]]:
    """Where a library's objects came from: a merged library's own record, or one entry for a
    library built in one go (its name, objects, trials per action and object, software version
    and, where given, the file's SHA-256)."""
    recorded = prior.metadata.get("provenance")
    if isinstance(recorded, list) and recorded:
        return [dict(p, via=name) if "via" not in p else dict(p) for p in recorded]
    trials: dict[str, dict[str, list[int]]] = {}
    for action, ap in prior.actions.items():
        objects = np.asarray(ap.observations.objects)
        trials[action] = {
            str(o): sorted(int(t) for t in ap.observations.trials[objects == o]) for o in ap.objects
        }
    entry: dict[str, Any] = {
        "source": name,
        "objects": prior.objects,
        "trials": trials,
        "software_version": prior.metadata.get("software_version"),
    }
    if digest is not None:
        entry["sha256"] = digest
    for key in ("data", "table"):
        if key in prior.metadata:
            entry[key] = prior.metadata[key]
    return [entry]


def _columns(prior: PriorKnowledge) -> dict[str, dict[str, int]]:
    return {
        a: {m: int(v.shape[1]) for m, v in ap.observations.modalities.items()}
        for a, ap in prior.actions.items()
    }


def _transforms(prior: PriorKnowledge) -> dict[str, dict[str, tuple[tuple[int, ...], int | None]]]:
    """Each action's transform settings (log columns, PCA components) of the modalities it
    has and transforms beyond z-scoring."""
    return {
        a: {
            m: (t.log_columns, t.pca_components)
            for m, t in ap.pipeline.transforms.items()
            if m in ap.observations.modalities and (t.log_columns or t.pca_components)
        }
        for a, ap in prior.actions.items()
    }


def _check_compatible(named: Sequence[tuple[str, PriorKnowledge]]) -> None:
    """One line naming the first difference that keeps the libraries apart."""
    first_name, first = named[0]
    owner: dict[str, str] = {o: first_name for o in first.objects}
    for name, other in named[1:]:
        if set(other.actions) != set(first.actions):
            only_a = sorted(set(first.actions) - set(other.actions))
            only_b = sorted(set(other.actions) - set(first.actions))
            raise IncompatiblePriorsError(
                f"{name} and {first_name} have other actions: "
                + "; ".join(
                    part
                    for part in (
                        f"only {first_name} has {', '.join(only_a)}" if only_a else "",
                        f"only {name} has {', '.join(only_b)}" if only_b else "",
                    )
                    if part
                )
            )
        for of, describe, differs, hint in (
            (_columns, _describe, "{action} has other feature columns", ""),
            (
                _transforms,
                _describe_transforms,
                "{action}'s features are transformed otherwise",
                ": this skin's features and another sensor's? A feature table's library takes "
                "--extraction as its features are",
            ),
        ):
            ours, theirs = of(first), of(other)
            for action in first.actions:
                if ours[action] != theirs[action]:
                    raise IncompatiblePriorsError(
                        f"{name} and {first_name}: action {differs.format(action=action)} "
                        f"({describe(theirs[action])} against {describe(ours[action])}){hint}"
                    )
        for key, what in (
            ("extraction", "features extracted with other settings"),
            ("feature_table_columns", "other feature tables' columns"),
        ):
            a, b = first.metadata.get(key), other.metadata.get(key)
            if a is not None and b is not None and a != b:
                raise IncompatiblePriorsError(
                    f"{name} and {first_name}: {what} ({_difference(b, a)})"
                )
        if other.feature_scale != first.feature_scale:
            raise IncompatiblePriorsError(
                f"{name} and {first_name}: another metric (feature scale {other.feature_scale!r} "
                f"against {first.feature_scale!r}); rebuild one with --prior-feature-scale "
                f"{first.feature_scale}"
            )
        defs_a = first.metadata.get("action_definitions") or {}
        defs_b = other.metadata.get("action_definitions") or {}
        for action in sorted(set(defs_a) & set(defs_b)):
            if defs_a[action] != defs_b[action]:
                raise IncompatiblePriorsError(
                    f"{name} and {first_name}: action {action} is another movement in each "
                    f"({_difference(defs_b[action], defs_a[action])})"
                )
        for o in other.objects:
            if o in owner:
                raise IncompatiblePriorsError(
                    f"{name} and {owner[o]} both hold an object named {o!r}; an object's name "
                    "is its identity in a library — rename one (or leave one out)"
                )
            owner[o] = name


def _describe_transforms(transforms: Mapping[str, Any]) -> str:
    parts = []
    for m, (logs, pca) in transforms.items():
        steps = ([f"log of columns {','.join(map(str, logs))}"] if logs else []) + (
            [f"PCA to {pca}"] if pca else []
        )
        if steps:
            parts.append(f"{m}: {', '.join(steps)}")
    return "; ".join(parts) or "z-scored only"


def _describe(columns: Mapping[str, Any]) -> str:
    return ", ".join(f"{m} ({d})" for m, d in columns.items())


def _difference(b: Any, a: Any) -> str:
    """The first field in which two recorded settings differ, as ``field: b vs a``."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        for key in sorted(set(a) | set(b), key=str):
            if a.get(key) != b.get(key):
                return f"{key}: {b.get(key)!r} against {a.get(key)!r}"
    return f"{b!r} against {a!r}"


def merge_priors(
    named: Sequence[tuple[str, PriorKnowledge]],
    *,
    gp: GPSettings | None = None,
    seed: int = 0,
    digests: Mapping[str, str] | None = None,
    progress: Any = None,
) -> PriorKnowledge:
    """One library of every object of ``named`` (name, prior knowledge) pairs — e.g. the file
    names — refitted on all their observations together. ``gp``: the settings of the fit
    (default: the first library's own, which fixes the metric every library shares). Raises
    :class:`~aptkt.errors.IncompatiblePriorsError` naming what keeps them apart."""
    if len(named) < 2:
        raise IncompatiblePriorsError("merging needs at least two prior-knowledge files")
    _check_compatible(named)
    first = named[0][1]
    gp = gp or first.gp_settings
    table = {
        action: Observations.concat([prior[action].observations for _, prior in named])
        for action in first.actions
    }
    # The library's own transforms: one built from a feature table (any sensor's) has none of
    # this skin's, and merging must not give it them.
    transforms = {
        m: ModalityTransform(log_columns=t.log_columns, pca_components=t.pca_components)
        for action in first.actions.values()
        for m, t in action.pipeline.transforms.items()
    }
    merged = PriorKnowledge.build(table, gp=gp, seed=seed, progress=progress, transforms=transforms)
    provenance = [
        entry
        for name, prior in named
        for entry in provenance_of(name, prior, (digests or {}).get(name))
    ]
    definitions: dict[str, Any] = {}
    for _, prior in named:
        definitions.update(prior.metadata.get("action_definitions") or {})
    merged.metadata.update(
        provenance=provenance,
        merged_from=[name for name, _ in named],
        merged_with=__version__,
    )
    for key in ("extraction", "feature_table_columns"):
        value = next((p.metadata[key] for _, p in named if key in p.metadata), None)
        if value is not None:
            merged.metadata[key] = value
    if definitions:
        merged.metadata["action_definitions"] = definitions
    return merged
