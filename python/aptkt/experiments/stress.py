"""The reproduction's stress tests of the cut-off (Fig. 11): the learner made to transfer the
*least* related old object, with λ forced to a fixed value, to show what the cut-off stops.
Nothing a user runs offers this: it exists to break the method on purpose."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

from aptkt.errors import InvalidInputError
from aptkt.learning import LearnerConfig
from aptkt.learning.transfer import SOURCE_CHOICES

__all__ = ["STRESS_FIELDS", "CutoffStressTest", "learner_config_from_dict", "with_stress"]

#: The settings only a stress test has.
STRESS_FIELDS = ("source_choice", "forced_lambda")


@dataclass(frozen=True)
class CutoffStressTest(LearnerConfig):
    """A learner whose transfers take the ``source_choice`` ("least" or "most") related old
    object and, once the cut-off has let one through, λ = ``forced_lambda`` instead of p̄
    (None: p̄)."""

    source_choice: str = "most"
    forced_lambda: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.source_choice not in SOURCE_CHOICES:
            raise InvalidInputError(
                f"source_choice must be one of {SOURCE_CHOICES}, got {self.source_choice!r}"
            )
        if self.forced_lambda is not None and not 0.0 <= self.forced_lambda <= 1.0:
            raise InvalidInputError(
                f"forced_lambda must be None or lie in [0, 1], got {self.forced_lambda}"
            )

    def _transfer_pick(self) -> tuple[str, float | None]:
        return self.source_choice, self.forced_lambda


def with_stress(config: LearnerConfig, settings: Mapping[str, Any]) -> LearnerConfig:
    """``config`` with ``settings`` applied, as a :class:`CutoffStressTest` when they include
    a stress test's own."""
    settings = dict(settings)
    stress = {k: settings.pop(k) for k in STRESS_FIELDS if k in settings}
    config = replace(config, **settings)
    if not stress or isinstance(config, CutoffStressTest):
        return replace(config, **stress)
    return CutoffStressTest(**{f.name: getattr(config, f.name) for f in fields(config)}, **stress)


def learner_config_from_dict(data: Mapping[str, Any]) -> LearnerConfig:
    """A learner's recorded settings (:meth:`LearnerConfig.to_dict`) read back, a stress
    test's as one."""
    stressed = any(k in data for k in STRESS_FIELDS)
    return (CutoffStressTest if stressed else LearnerConfig).from_dict(data)
