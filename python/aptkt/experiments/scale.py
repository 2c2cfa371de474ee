"""How large the reproduced experiments are: the paper's sizes, or a quick reduced version.

The paper's designs (§5.3–5.6), with our reading of what it leaves open (docs/reproduce.md):

* fig6: ``groups`` groups of ``fig6_group_size`` objects drawn from all objects, each learned
  ``fig6_trials`` times per action and model (multi-modal, each single modality), no transfer;
  ``fig6_budget`` observations after the initial round, collected in random order.
* fig7/fig8: ``groups`` groups of ``n_priors`` prior objects × ``trials`` trials, APTKT vs
  baseline, ``budget`` observations after the initial round; fig8 one action at a time.
* fig9: ``prior_counts`` priors (``groups`` groups each, or every possible group when fewer
  exist) × ``trials``; baseline, APTKT, APTKT with auxiliary features.
* fig10/fig11: per action and for all actions, the ``dissimilar_count`` priors least similar
  to the new objects; ``fig11_trials`` trials of APTKT vs baseline.

Trials ``0 .. repetitions/2 - 1`` of every object form the pool (and the priors' data); the
rest is the test set (the paper: 20 test observations per action and object).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

from aptkt.actions import PAPER_ACTIONS
from aptkt.errors import InvalidInputError
from aptkt.learning.config import LearnerConfig
from aptkt.sim.objects import default_library

__all__ = ["Scale"]


@dataclass(frozen=True)
class Scale:
    name: str
    priors: tuple[str, ...]
    new_objects: tuple[str, ...]
    actions: tuple[str, ...]
    repetitions: int = 40
    budget: int = LearnerConfig.budget
    groups: int = 10
    trials: int = 5
    n_priors: int = 3
    prior_counts: tuple[int, ...] = (3, 5, 7, 10)
    fig6_group_size: int = 5
    fig6_trials: int = 10
    fig6_budget: int = 40
    fig11_trials: int = 10
    dissimilar_count: int = 3
    eps_neg: float = LearnerConfig.eps_neg
    eps_explor: float | None = LearnerConfig.eps_explor

    def __post_init__(self) -> None:
        if self.repetitions < 2:
            raise InvalidInputError("repetitions must be >= 2 (a pool and a test half)")
        if len(self.new_objects) < 2:
            raise InvalidInputError("at least two new objects are needed")
        if not 1 <= self.n_priors <= len(self.priors):
            raise InvalidInputError(f"n_priors must lie in 1..{len(self.priors)}")
        if any(not 1 <= n <= len(self.priors) for n in self.prior_counts):
            raise InvalidInputError(f"prior_counts must lie in 1..{len(self.priors)}")
        if not 2 <= self.fig6_group_size <= len(self.priors) + len(self.new_objects):
            raise InvalidInputError("fig6_group_size must lie in 2..number of objects")
        if not 1 <= self.dissimilar_count <= len(self.priors):
            raise InvalidInputError(f"dissimilar_count must lie in 1..{len(self.priors)}")
        for name in ("budget", "fig6_budget"):
            if getattr(self, name) < 0:
                raise InvalidInputError(f"{name} must be >= 0")
        for name in ("groups", "trials", "fig6_trials", "fig11_trials"):
            if getattr(self, name) < 1:
                raise InvalidInputError(f"{name} must be >= 1")
        unknown = [a for a in self.actions if a not in PAPER_ACTIONS]
        if unknown:
            raise InvalidInputError(
                f"unknown action(s) {unknown}; the experiments use the paper's {list(PAPER_ACTIONS)}"
            )

    @property
    def objects(self) -> tuple[str, ...]:
        return tuple(self.priors) + tuple(self.new_objects)

    @property
    def pool_trials(self) -> tuple[int, ...]:
        return tuple(range(self.repetitions // 2))

    @property
    def test_trials(self) -> tuple[int, ...]:
        return tuple(range(self.repetitions // 2, self.repetitions))

    def to_dict(self) -> dict[str, Any]:
        return {
            **asdict(self),
            "pool_trials": list(self.pool_trials),
            "test_trials": list(self.test_trials),
        }

    @classmethod
    def full(cls) -> Scale:
        """The paper's sizes on the simulated world's 10 prior and 5 new objects."""

        lib = default_library()
        return cls(
            "full", tuple(lib.with_role("prior")), tuple(lib.with_role("new")), tuple(PAPER_ACTIONS)
        )

    @classmethod
    def quick(cls) -> Scale:
        """A reduced size for tests and CI: 4 priors, 3 new objects, 3 actions, 6 trials."""
        return cls(
            "quick",
            priors=("rough_sponge", "paper_box", "metal_toolbox", "wooden_board"),
            new_objects=("smooth_sponge", "hard_box", "biscuit_box"),
            actions=("P2", "S4", "C1"),
            repetitions=6,
            budget=4,
            groups=2,
            trials=2,
            n_priors=3,
            prior_counts=(2, 4),
            fig6_group_size=3,
            fig6_trials=2,
            fig6_budget=3,
            fig11_trials=2,
            dissimilar_count=2,
        )

    def with_(self, **changes: Any) -> Scale:
        return replace(self, **changes)
