"""Prior knowledge for the experiments: one file per group of prior objects, built once.

A :class:`PriorTask` names everything the prior knowledge depends on (data set content, prior
objects, actions, trials, GP settings, seed); its file name is a hash of that, so the file is
built once per output directory and every run that needs the same group shares it. Building
is a plain function of the task, so it runs on local worker processes or on a Dask cluster
like the learning runs.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from aptkt.experiments.run_store import canonical_json
from aptkt.learning import GPSettings, PriorKnowledge
from aptkt.learning.dataset import load_observations

__all__ = ["PriorTask", "build_prior"]


@dataclass(frozen=True)
class PriorTask:
    """Build the prior knowledge of ``objects`` from their observations in ``trials``."""

    data: str
    fingerprint: str
    objects: tuple[str, ...]
    actions: tuple[str, ...]
    trials: tuple[int, ...]
    seed: int
    directory: str
    gp: dict[str, Any] | None = None

    @property
    def key(self) -> str:
        content = {
            "data": self.fingerprint,
            "objects": list(self.objects),
            "actions": list(self.actions),
            "trials": list(self.trials),
            "seed": self.seed,
            "gp": self.gp_settings().to_dict(),
        }
        return hashlib.sha256(canonical_json(content).encode()).hexdigest()[:20]

    @property
    def path(self) -> str:
        return str(Path(self.directory) / f"prior-{len(self.objects)}-{self.key}.npz")

    def gp_settings(self) -> GPSettings:
        return GPSettings(**(self.gp or {}))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def build_prior(task: PriorTask) -> str:
    """Build and save the task's prior knowledge (atomically) unless its file exists; returns
    the file's path."""
    path = Path(task.path)
    if path.exists():
        return str(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table = load_observations(
        task.data, actions=task.actions, objects=task.objects, trials=task.trials
    )
    prior = PriorKnowledge.build(table, task.objects, gp=task.gp_settings(), seed=task.seed)
    prior.metadata["objects"] = list(task.objects)
    prior.metadata["trials"] = list(task.trials)
    prior.metadata["data_fingerprint"] = task.fingerprint
    prior.save(path)
    return str(path)
