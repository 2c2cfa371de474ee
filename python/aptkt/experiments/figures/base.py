"""What every figure of the reproduction shares: the context of a reproduction (scale, seed,
data, output directory), the learning methods, and how runs and prior knowledge are named."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aptkt.experiments.aggregate import Estimate
from aptkt.experiments.plots import save_figure
from aptkt.experiments.priors import PriorTask
from aptkt.experiments.report import TOO_FEW, too_few
from aptkt.experiments.runs import RunSpec
from aptkt.experiments.sampling import derive_seed
from aptkt.experiments.scale import Scale
from aptkt.experiments.stress import with_stress
from aptkt.experiments.tables import write_csv
from aptkt.learning import GPSettings, LearnerConfig

__all__ = ["Context", "Plan", "METHODS", "Section", "Headline", "STRESS_CUTOFF", "STRESS_NO_CUTOFF"]

STRESS_NO_CUTOFF = "λ=1 least related, no cut-off"
STRESS_CUTOFF = "λ=1 least related, cut-off"

#: The compared learners (paper Fig. 9's names and colours): the baseline (the paper's: the
#: multi-modal kernel and nothing of the prior), APTKT (Eq. 2–3), APTKT with the prior models'
#: posteriors as auxiliary features (Eq. 5). Beyond the paper: the control (the prior's feature
#: space without transfer, so that it and APTKT differ by the transfer alone), and two stress
#: tests of the cut-off: λ forced to 1 from the least related prior, without any cut-off (ε_neg = 0
#: and no evidence test) and with the learner's.
METHODS: Mapping[str, Mapping[str, Any]] = {
    "baseline": {"transfer": "none"},
    "control": {"transfer": "control"},
    "APTKT": {"transfer": "paper"},
    "APTKT+aux": {"transfer": "paper", "auxiliary": True},
    STRESS_NO_CUTOFF: {
        "transfer": "paper",
        "source_choice": "least",
        "forced_lambda": 1.0,
        "eps_neg": 0.0,
        "cutoff": "paper",
    },
    STRESS_CUTOFF: {"transfer": "paper", "source_choice": "least", "forced_lambda": 1.0},
}


@dataclass
class Context:
    """One reproduction: its sizes, root seed, data set and output directory."""

    scale: Scale
    seed: int
    data: str
    fingerprint: str
    output: Path
    index: Mapping[str, int]  # each object's number in the paper (1-10 priors, 11-15 new)
    #: The learner every method starts from (the reading and its choices; docs/method.md).
    base: LearnerConfig = field(default_factory=LearnerConfig)
    cache: dict[str, Any] = field(default_factory=dict)  # results one figure computes for another

    @property
    def gp(self) -> GPSettings:
        return self.base.gp

    def figure_dir(self, name: str) -> Path:
        d = self.output / name
        d.mkdir(parents=True, exist_ok=True)
        return d

    def write_figure(
        self,
        name: str,
        fig: Any,
        rows: Sequence[Mapping[str, Any]],
        curve_rows: Sequence[Mapping[str, Any]],
    ) -> list[str]:
        """A figure's plot (PNG, SVG), every step of every run (``results.csv``) and its curves
        (``curves.csv``) in its directory; returns the files, relative to the output."""
        out = self.figure_dir(name)
        files = [str(p.relative_to(self.output)) for p in save_figure(fig, out / name)]
        # The transfer decisions (nested, per action and object) stay in the run store's JSON.
        write_csv(
            out / "results.csv",
            ({k: v for k, v in r.items() if k != "final_transfer"} for r in rows),
        )
        write_csv(out / "curves.csv", curve_rows)
        return files + [f"{name}/results.csv", f"{name}/curves.csv"]

    def seed_for(self, *keys: int | str) -> int:
        return derive_seed(self.seed, *keys)

    def prior_task(self, objects: Sequence[str]) -> PriorTask:
        """Prior knowledge of these objects from their pool trials, every action."""
        ordered = tuple(o for o in self.scale.objects if o in set(objects))
        return PriorTask(
            data=self.data,
            fingerprint=self.fingerprint,
            objects=ordered,
            actions=tuple(self.scale.actions),
            trials=self.scale.pool_trials,
            seed=self.seed,
            directory=str(self.output / "priors"),
            gp=self.gp.to_dict(),
        )

    def learner(
        self, method: str, *, budget: int | None = None, seed: int = 0, **overrides: Any
    ) -> LearnerConfig:
        settings = {
            "eps_neg": self.scale.eps_neg,
            "eps_explor": self.scale.eps_explor,
            "budget": self.scale.budget if budget is None else budget,
            "seed": seed,
            **METHODS.get(method, {}),
            **overrides,
        }
        return with_stress(self.base, settings)

    def spec(
        self,
        method: str,
        config: LearnerConfig,
        actions: Sequence[str],
        new_objects: Sequence[str],
        prior: PriorTask | None,
        seed: int,
        tags: Mapping[str, Any],
    ) -> RunSpec:
        return RunSpec(
            method=method,
            config=config,
            data=self.data,
            actions=tuple(actions),
            new_objects=tuple(new_objects),
            pool_trials=self.scale.pool_trials,
            test_trials=self.scale.test_trials,
            prior=None if prior is None else prior.path,
            pool_seed=seed,
            tags=dict(tags),
        )

    def numbers(self, objects: Sequence[str]) -> str:
        """Objects as the paper's numbers, in increasing order, e.g. ``{1, 5, 10}``."""
        return "{" + ", ".join(str(n) for n in sorted(self.index[o] for o in objects)) + "}"

    def label(self, obj: str) -> str:
        """An object's number and name, e.g. ``2 rough sponge``."""
        return f"{self.index[obj]} {obj.replace('_', ' ')}"

    def names(self, objects: Sequence[str], sep: str = ", ") -> str:
        """Objects by number and name, in the paper's order, e.g. ``1 ceramic tile, 5 cork board``."""
        return sep.join(self.label(o) for o in sorted(objects, key=self.index.__getitem__))

    @property
    def chance(self) -> float:
        """Accuracy of guessing among the new objects (the learning curves' floor)."""
        return 1.0 / len(self.scale.new_objects)


@dataclass
class Plan:
    """The prior knowledge a figure needs and its runs."""

    priors: list[PriorTask] = field(default_factory=list)
    specs: list[RunSpec] = field(default_factory=list)


@dataclass
class Headline:
    """One of the paper's claims beside our number and a verdict."""

    figure: str
    claim: str
    paper: str
    ours: str
    verdict: str
    #: The estimates the verdict rests on: if any has too few runs, the verdict says so instead.
    evidence: Sequence[Estimate] = ()
    #: Where the claim differs: what this run measured that accounts for it (computed from its
    #: own results, never a fixed text), or "" where the run holds no such measurement.
    why: str = ""

    def __post_init__(self) -> None:
        if self.evidence and too_few(*self.evidence) and not self.undecided:
            n = min(e.n for e in self.evidence)
            unit = next(e.unit for e in self.evidence if e.n == n)
            self.verdict = f"{TOO_FEW} ({n} {unit})"

    @property
    def agrees(self) -> bool:
        return self.verdict.startswith("agrees")

    @property
    def undecided(self) -> bool:
        return self.verdict.startswith(TOO_FEW)


@dataclass
class Section:
    """A figure's part of the report: headline comparisons, Markdown body, files written, and
    the computed numbers (for summary.json and tests)."""

    figure: str
    title: str
    headlines: list[Headline]
    body: str
    files: list[str]
    numbers: dict[str, Any]
