"""Fit the simulated world's noise to a real sensor's table (``aptkt dataset fit-noise``).

The table's noise is summarised by :func:`~aptkt.experiments.noise_profile.noise_profile`'s three
figures, each the median over its actions and modalities: how far apart the objects lie in units
of the noise (separation), how much a run's trials move together (drift) and how much the noise
differs from object to object (heterogeneity). The world's :class:`~aptkt.sim.noise.NoiseLevel`
has one number for each, and each figure answers mainly to its own number:

- separation is the objects' spread over the within-object noise, so it falls as 1 / ``trial``;
- drift is the halves' difference over stationary noise's, so its square less one grows with the
  wander's share of the noise, (``drift`` / ``trial``)²;
- heterogeneity is the spread of log object noise over what estimation alone gives, and an
  object's repeatability factor ``exp(objects · z)`` adds its spread in quadrature.

A probe data set is simulated at the current level and measured; each number is then moved to
where its relation says the figure meets the table's (a fixed-point step on all three at
once). The probe measured closest to the table is the fit, with what it reached.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.actions import PAPER_ACTIONS
from aptkt.errors import ConfigError
from aptkt.experiments.noise_profile import NoiseProfile, noise_profile
from aptkt.learning.observations import ObservationTable
from aptkt.sim.noise import MAX_LEVEL, NoiseLevel

__all__ = ["NoiseSummary", "NoiseFit", "summarise", "next_level", "fit_noise"]

#: log10(e): a natural-log spread in the decades that heterogeneity is measured in.
_DECADE = 1 / math.log(10)


@dataclass(frozen=True)
class NoiseSummary:
    """A data set's noise in three figures (medians over its actions and modalities)."""

    separation: float
    drift: float
    heterogeneity: float
    #: Trials per object and action the figures were measured on (the median).
    trials: int

    def distance(self, other: NoiseSummary) -> float:
        """How far two summaries are apart: the largest ratio between their figures, in log."""
        return max(
            abs(math.log(max(getattr(self, k), 1e-9) / max(getattr(other, k), 1e-9)))
            for k in ("separation", "drift", "heterogeneity")
        )

    def as_dict(self) -> dict[str, float | int]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class NoiseFit:
    """The fitted level, the table's figures and what every probe measured."""

    level: NoiseLevel
    target: NoiseSummary
    reached: NoiseSummary
    probes: tuple[tuple[NoiseLevel, NoiseSummary], ...]

    def as_dict(self) -> dict[str, Any]:
        return {
            "level": self.level.to_dict(),
            "target": self.target.as_dict(),
            "reached": self.reached.as_dict(),
            "probes": [{"level": lv.to_dict(), **s.as_dict()} for lv, s in self.probes],
        }


def summarise(profiles: Sequence[NoiseProfile], trials: int) -> NoiseSummary:
    if not profiles:
        raise ConfigError(
            "no action and modality of the table can be profiled: each needs at least 2 objects "
            "with 4 or more trials each"
        )
    return NoiseSummary(
        separation=float(np.median([p.separation for p in profiles])),
        drift=float(np.median([p.drift for p in profiles])),
        heterogeneity=float(np.median([p.heterogeneity for p in profiles])),
        trials=int(trials),
    )


def trials_per_object(table: ObservationTable) -> int:
    counts = [
        int(n)
        for obs in table.values()
        for n in np.unique(np.asarray(obs.objects), return_counts=True)[1]
    ]
    return int(np.median(counts)) if counts else 0


def _chance(trials: int) -> float:
    """The spread of log10 of a sample SD from estimation alone (noise_profile's unit)."""
    return 0.4343 / math.sqrt(2 * max(trials - 1, 1))


def next_level(level: NoiseLevel, measured: NoiseSummary, target: NoiseSummary) -> NoiseLevel:
    """Each number moved to where its relation (module docstring) puts the table's figure."""
    trial = level.trial * measured.separation / target.separation
    # The wander's share of the noise, (drift / trial)², scaled to what the table's drift needs.
    excess_now, excess_wanted = measured.drift**2 - 1, target.drift**2 - 1
    if excess_wanted <= 0:
        drift = 0.0
    elif excess_now <= 0.01 or level.drift == 0:
        drift = 2 * max(level.drift, 0.5) * trial / level.trial  # no wander measured: more
    else:
        drift = level.drift / level.trial * math.sqrt(excess_wanted / excess_now) * trial
    # The object factor adds its spread (in the measure's unit) in quadrature to the rest.
    chance = _chance(measured.trials)
    added = level.objects * _DECADE / chance
    rest = max(measured.heterogeneity**2 - added**2, 0.0)
    missing = max(target.heterogeneity**2 - rest, 0.0)
    objects = math.sqrt(missing) * chance / _DECADE
    # (Within the world's range: a table beyond it gets the nearest level, and the fit reports
    # what that level reached.)
    wanted = {"trial": trial, "drift": drift, "objects": objects}
    return NoiseLevel(**{k: min(v, MAX_LEVEL[k]) for k, v in wanted.items()})


def simulated_summary(
    level: NoiseLevel,
    *,
    trials: int,
    seed: int = 0,
    objects: Sequence[str] | None = None,
    actions: Sequence[str] | None = None,
    jobs: int = 1,
    workdir: Path | None = None,
) -> NoiseSummary:
    """Simulate a probe data set at ``level`` (the default library's objects and the paper's
    actions unless given) and summarise its noise. The probe is deleted afterwards."""
    from aptkt.experiments.executors import make_executor
    from aptkt.learning.dataset import extract_features, load_observations
    from aptkt.runtime.generation import GenerationPlan, generate
    from aptkt.sim.objects import default_library

    names = tuple(objects) if objects is not None else tuple(default_library())
    acts = tuple(PAPER_ACTIONS[a] for a in (actions or PAPER_ACTIONS))
    plan = GenerationPlan(names, acts, trials, seed, world_options={"noise": level.to_dict()})
    with tempfile.TemporaryDirectory(prefix="aptkt-noise-", dir=workdir) as tmp:
        path = Path(tmp) / "probe.h5"
        generate(path, plan, jobs=jobs, progress=False)
        executor = make_executor(jobs)
        try:
            extract_features(path, progress=False, parallel_map=executor.imap_unordered)
        finally:
            executor.close()
        table = load_observations(path, extract_missing=False)
    return summarise(noise_profile(table), trials)


def fit_noise(
    table: ObservationTable,
    *,
    probes: int = 3,
    trials: int | None = None,
    seed: int = 0,
    jobs: int = 1,
    workdir: Path | None = None,
    say: Callable[[str], None] = lambda _: None,
    simulate: Callable[..., NoiseSummary] | None = None,
) -> NoiseFit:
    """The world's noise level whose probe comes closest to ``table``'s figures (``simulate``:
    how a probe is made and measured, :func:`simulated_summary` unless given)."""
    simulate = simulate or simulated_summary
    if probes < 1:
        raise ConfigError(f"probes must be >= 1, got {probes}")
    target = summarise(noise_profile(table), trials_per_object(table))
    if not target.separation > 1e-9:  # (rounding: identical objects give about 1e-16)
        raise ConfigError(
            "the table's objects do not differ (separation 0): no noise level can match it"
        )
    n = trials if trials is not None else min(max(target.trials, 8), 40)
    say(
        f"the table: separation {target.separation:.2f}, drift {target.drift:.2f}, "
        f"heterogeneity {target.heterogeneity:.2f} ({target.trials} trials per object)"
    )
    level, seen = NoiseLevel(), []
    for k in range(1, probes + 1):
        measured = simulate(level, trials=n, seed=seed, jobs=jobs, workdir=workdir)
        seen.append((level, measured))
        say(
            f"probe {k}/{probes}: trial {level.trial:.3f}, drift {level.drift:.3f}, objects "
            f"{level.objects:.3f} -> separation {measured.separation:.2f}, drift "
            f"{measured.drift:.2f}, heterogeneity {measured.heterogeneity:.2f}"
        )
        level = next_level(level, measured, target)
    best_level, best = min(seen, key=lambda p: p[1].distance(target))
    return NoiseFit(level=best_level, target=target, reached=best, probes=tuple(seen))
