"""Feature observations as plain arrays: the learner's input, whatever produced it.

An observation of an exploratory action is one vector per modality (e.g. ``force``: the mean
normal force, ``thermal``: the temperature curve). :class:`Observations` holds many observations
of one action with the object each came from; an :data:`ObservationTable` maps action names to
them. Users with another sensor build these from their own arrays (see
:meth:`Observations.from_arrays`) — nothing here depends on the simulator or the skin.

Observations remember what computed them (``extraction``): this package's extraction of this
skin's recordings names itself (:data:`~aptkt.learning.pipeline.SKIN_EXTRACTION`), and only such
features get this skin's transforms by default; observations built from other arrays say
nothing (None) and are z-scored as they are, whatever their modalities are called.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError

__all__ = ["Observations", "ObservationTable", "common_extraction", "validate_table"]


@dataclass
class Observations:
    """Observations of one action: ``modalities[name]`` is ``(n, d_name)``; ``objects`` is
    ``(n,)``; ``extraction`` names what computed the features (None: not said)."""

    action: str
    modalities: dict[str, np.ndarray]
    objects: np.ndarray
    trials: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    extraction: str | None = None

    def __post_init__(self) -> None:
        if self.extraction is not None and not (
            isinstance(self.extraction, str) and self.extraction
        ):
            raise InvalidInputError(
                f"action {self.action!r}: extraction must be a name or None, got "
                f"{self.extraction!r}"
            )
        self.objects = np.asarray(self.objects).astype(str)
        n = self.objects.shape[0]
        if self.objects.ndim != 1:
            raise InvalidInputError(f"action {self.action!r}: objects must be 1-D")
        if not self.modalities:
            raise InvalidInputError(f"action {self.action!r}: at least one modality is needed")
        mods = {}
        for name, values in self.modalities.items():
            arr = np.asarray(values, dtype=np.float64)
            if arr.ndim == 1:
                arr = arr[:, None]
            if arr.ndim != 2 or arr.shape[0] != n:
                raise InvalidInputError(
                    f"action {self.action!r}, modality {name!r}: expected shape ({n}, d), got {arr.shape}"
                )
            bad = np.argwhere(~np.isfinite(arr))
            if bad.size:
                r, c = bad[0]
                raise InvalidInputError(
                    f"action {self.action!r}, modality {name!r}: non-finite value {arr[r, c]} "
                    f"in observation {r} (object {str(self.objects[r])!r}), column {c}"
                )
            mods[str(name)] = arr
        self.modalities = mods
        trials = np.asarray(self.trials, dtype=np.int64)
        self.trials = trials if trials.shape == (n,) else np.arange(n, dtype=np.int64)

    @classmethod
    def from_arrays(
        cls,
        action: str,
        objects: Sequence[Any],
        trials: Sequence[int] | None = None,
        **modalities: Any,
    ) -> Observations:
        """``Observations.from_arrays("P1", objects, force=f, thermal=t)``."""
        return cls(
            action,
            dict(modalities),
            np.asarray(objects),
            np.asarray(trials if trials is not None else []),
        )

    def __repr__(self) -> str:
        columns = ", ".join(f"{m} {v.shape[1]}" for m, v in self.modalities.items())
        said = f", extraction {self.extraction!r}" if self.extraction is not None else ""
        return (
            f"Observations({self.action!r}: {len(self)} observations of "
            f"{len(self.object_names)} objects; columns {columns}{said})"
        )

    def __len__(self) -> int:
        return int(self.objects.shape[0])

    @property
    def modality_names(self) -> tuple[str, ...]:
        return tuple(self.modalities)

    @property
    def object_names(self) -> list[str]:
        return sorted(set(self.objects.tolist()))

    def take(self, index: Any) -> Observations:
        return Observations(
            self.action,
            {k: v[index] for k, v in self.modalities.items()},
            self.objects[index],
            self.trials[index],
            self.extraction,
        )

    def of_objects(self, objects: Iterable[str]) -> Observations:
        return self.take(np.isin(self.objects, list(objects)))

    def row(self, i: int) -> dict[str, np.ndarray]:
        return {k: v[i] for k, v in self.modalities.items()}

    @classmethod
    def concat(cls, parts: Sequence[Observations]) -> Observations:
        if not parts:
            raise InvalidInputError("nothing to concatenate")
        names = parts[0].modality_names
        for p in parts[1:]:
            if p.action != parts[0].action or p.modality_names != names:
                raise InvalidInputError(
                    "can only concatenate observations of the same action and modalities"
                )
        return cls(
            parts[0].action,
            {k: np.concatenate([p.modalities[k] for p in parts]) for k in names},
            np.concatenate([p.objects for p in parts]),
            np.concatenate([p.trials for p in parts]),
            common_extraction(parts),
        )

    @classmethod
    def single(
        cls,
        action: str,
        obj: str,
        observation: Mapping[str, np.ndarray],
        trial: int = 0,
        extraction: str | None = None,
    ) -> Observations:
        return cls(
            action,
            {k: np.asarray(v, dtype=np.float64)[None, :] for k, v in observation.items()},
            np.array([obj]),
            np.array([trial]),
            extraction,
        )

    def to_npz(self, prefix: str) -> dict[str, np.ndarray]:
        out = {f"{prefix}/objects": self.objects.astype("U"), f"{prefix}/trials": self.trials}
        for k, v in self.modalities.items():
            out[f"{prefix}/modality/{k}"] = v
        return out

    @classmethod
    def from_npz(cls, action: str, arrays: Mapping[str, np.ndarray], prefix: str) -> Observations:
        mods = {
            key[len(f"{prefix}/modality/") :]: np.asarray(arrays[key])
            for key in arrays
            if key.startswith(f"{prefix}/modality/")
        }
        return cls(
            action,
            mods,
            np.asarray(arrays[f"{prefix}/objects"]),
            np.asarray(arrays[f"{prefix}/trials"]),
        )


#: Observations of several actions, by action name.
ObservationTable = Mapping[str, Observations]


def common_extraction(parts: Iterable[Observations]) -> str | None:
    """What computed all of ``parts`` (None if none says). Parts that do not say (e.g. read
    from an older file) take the others' word; two different extractions do not measure in
    one space, so they are an error."""
    said = sorted({p.extraction for p in parts if p.extraction is not None})
    if len(said) > 1:
        raise InvalidInputError(
            f"observations of different extractions ({', '.join(said)}) cannot be pooled"
        )
    return said[0] if said else None


def validate_table(table: ObservationTable) -> None:
    for name, obs in table.items():
        if obs.action != name:
            raise InvalidInputError(
                f"table entry {name!r} holds observations of action {obs.action!r}"
            )
