"""Every parameter of a learning run, recorded with its results."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from aptkt.gp import DEFAULTS, LaplaceGPC
from aptkt.learning.transfer import TRANSFER_MODES

__all__ = ["GPSettings", "LearnerConfig"]


@dataclass(frozen=True)
class GPSettings:
    """How the observation models (one-vs-all Laplace GPCs) are fitted."""

    n_restarts: int = DEFAULTS.n_restarts
    max_iter: int = DEFAULTS.max_iter
    length_scale: float | str = DEFAULTS.length_scale
    signal_variance: float = DEFAULTS.signal_variance
    approximation: str = DEFAULTS.approximation
    n_jobs: int | None = DEFAULTS.n_jobs

    def make(self, modalities: Mapping[str, list[int]], random_state: int) -> LaplaceGPC:
        return LaplaceGPC(
            length_scale=self.length_scale,
            signal_variance=self.signal_variance,
            modalities=dict(modalities),
            n_restarts=self.n_restarts,
            max_iter=self.max_iter,
            approximation=self.approximation,
            random_state=random_state,
            n_jobs=self.n_jobs,
        )


@dataclass(frozen=True)
class LearnerConfig:
    """Parameters of APTKT (and of the baseline, which is ``transfer="none"``).

    eps_neg : the cut-off of Eq. 3 below which no prior object is transferred.
    eps_explor : probability of a uniformly random (action, object) pick (Eq. 4).
    budget : observations collected by active selection after the initial round (which
        observes every action once on every new object).
    transfer : "paper" (Eq. 2–3) or "none" (the baseline).
    auxiliary : append the prior models' posteriors as an extra modality (Eq. 5).
    patience : stop early when the mean uncertainty over all pairs has not decreased for this
        many consecutive observations (None: always spend the budget).
    seed : seeds exploration and the GP optimiser starts.
    modalities : use only these modalities in the new objects' models (e.g. ``("force",)`` for a
        single-modality model as in Fig. 6); None: every modality of each action. The prior
        models always see all of theirs.
    """

    eps_neg: float = 0.4
    eps_explor: float = 0.1
    budget: int = 40
    transfer: str = "paper"
    auxiliary: bool = False
    patience: int | None = None
    seed: int = 0
    modalities: tuple[str, ...] | None = None
    gp: GPSettings = field(default_factory=GPSettings)

    def __post_init__(self) -> None:
        if self.transfer not in TRANSFER_MODES:
            raise ValueError(f"transfer must be one of {TRANSFER_MODES}, got {self.transfer!r}")
        for name in ("eps_neg", "eps_explor"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {v}")
        if self.budget < 0:
            raise ValueError(f"budget must be >= 0, got {self.budget}")
        if self.modalities is not None:
            object.__setattr__(self, "modalities", tuple(str(m) for m in self.modalities))
            if not self.modalities:
                raise ValueError("modalities must name at least one modality (or be None)")
        if self.patience is not None and self.patience < 1:
            raise ValueError(f"patience must be None or >= 1, got {self.patience}")

    @property
    def uses_prior(self) -> bool:
        return self.transfer != "none" or self.auxiliary

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LearnerConfig:
        data = dict(data)
        gp = GPSettings(**data.pop("gp", {}))
        known = {f.name for f in fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown learner setting(s): {sorted(unknown)}")
        return cls(gp=gp, **data)
