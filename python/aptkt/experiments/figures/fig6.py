"""Fig. 6: the multi-modal kernel vs each single modality, per action (paper §5.3).

``groups`` groups of ``fig6_group_size`` objects drawn from all objects (prior and new alike),
each learned ``fig6_trials`` times per action with four observation models: the multi-modal
kernel (Eq. 1) and each of the action's modalities alone (an RBF on that modality). No prior
knowledge. The observations are collected in random order (ε_explor = 1), so within a trial
every model sees exactly the same observations and the comparison is of the models alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from aptkt.actions import PAPER_ACTIONS
from aptkt.experiments.aggregate import collect, difference, estimate, mean_over_panels
from aptkt.experiments.figures.analysis import Analysis, hide_unused, panel_grid
from aptkt.experiments.figures.base import Context, Headline, Plan
from aptkt.experiments.figures.common import plot_panel
from aptkt.experiments.report import PAPER, ci, listed, markdown_table
from aptkt.experiments.sampling import draw_groups

NAME = "fig6"
TITLE = "multi-modal kernel vs single modalities"
#: The paper's names of the models (Fig. 6) and the modalities each uses (None: all).
KINDS: Mapping[str, tuple[str, ...] | None] = {
    "Multi": None,
    "STIF": ("force",),
    "Texture": ("texture",),
    "Thermal-C": ("thermal",),
}
XLABEL = "observations of the action (all objects)"


def kinds(action: str) -> list[str]:
    mods = PAPER_ACTIONS[action].modalities
    return [k for k, m in KINDS.items() if m is None or m[0] in mods]


def groups(ctx: Context) -> list[tuple[str, ...]]:
    s = ctx.scale
    return draw_groups(s.objects, s.fig6_group_size, s.groups, ctx.seed_for("fig6-groups"))


def plan(ctx: Context) -> Plan:
    plan = Plan()
    s = ctx.scale
    for g, group in enumerate(groups(ctx)):
        for t in range(s.fig6_trials):
            seed = ctx.seed_for("fig6", g, t)
            for a in s.actions:
                for k in kinds(a):
                    cfg = ctx.learner(
                        "baseline",
                        budget=s.fig6_budget,
                        seed=seed,
                        eps_explor=1.0,
                        modalities=KINDS[k],
                    )
                    tags = {
                        "figure": NAME,
                        "panel": a,
                        "group": g,
                        "run": t,
                        "objects": ",".join(group),
                    }
                    plan.specs.append(ctx.spec(k, cfg, (a,), group, None, seed, tags))
    return plan


def _category(e) -> str:
    if not math.isfinite(e.low):
        return "n/a"
    return "beats" if e.significant_positive else "worse" if e.significant_negative else "matches"


class _Fig6(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        self.actions = list(self.ctx.scale.actions)
        self.per_action = {a: self._action(a) for a in self.actions}
        for a in self.actions:
            self.keep_curves({"panel": a}, self.per_action[a]["curves"])
        # The averaged panel: per run (group, run), each model's mean over the actions it
        # applies to.
        self.average = {}
        for k in KINDS:
            have = [d["curves"][k] for d in self.per_action.values() if k in d["curves"]]
            if have:
                self.average[k] = mean_over_panels(have)
        self.keep_curves({"panel": "average"}, self.average)
        self.cats = {a: _category(self.per_action[a]["vs_best"]) for a in self.actions}

    def _action(self, a: str) -> dict[str, Any]:
        curves = {
            k: collect(self.rows, {"panel": a, "method": k}, x="n_observations") for k in kinds(a)
        }
        singles = [k for k in curves if k != "Multi"]
        overall = {k: float(np.nanmean(c.run_means())) for k, c in curves.items()}
        best = max(singles, key=lambda k: overall[k])
        diff = difference(curves["Multi"], curves[best])
        units = diff.units(0)
        return {
            "curves": curves,
            "best_single": best,
            "overall": overall,
            "vs_best": estimate(diff.run_means(), units),
            "vs_best_final": estimate(diff.values[:, -1], units),
            "final": {k: float(np.nanmean(c.values[:, -1])) for k, c in curves.items()},
        }

    def draw(self) -> list[str]:
        n = len(self.actions) + 1
        fig, axes = panel_grid(n)
        chance = 1.0 / self.ctx.scale.fig6_group_size  # each run tells one group's objects apart
        for ax, a in zip(axes, self.actions):
            curves = self.per_action[a]["curves"]
            plot_panel(ax, curves, a, chance=chance, xlabel=XLABEL, legend=False)
        # every model: the legend
        plot_panel(
            axes[len(self.actions)],
            self.average,
            "averaged over actions",
            chance=chance,
            xlabel=XLABEL,
        )
        hide_unused(axes, n)
        fig.suptitle("Fig. 6 — multi-modal combination (Multi) vs single modalities, no transfer")
        fig.tight_layout()
        return self.write(fig)

    def headlines(self) -> list[Headline]:
        actions, cats, per_action = self.actions, self.cats, self.per_action
        worse = [a for a in actions if cats[a] == "worse"]
        paper_cat = {
            **{a: "beats" for a in PAPER["fig6_beats"]},
            **{a: "matches" for a in PAPER["fig6_matches"]},
        }
        mismatched = [a for a in actions if a in paper_cat and cats[a] != paper_cat[a]]
        evidence = [per_action[a]["vs_best"] for a in actions]
        return [
            Headline(
                NAME,
                "the multi-modal kernel matches or beats the best single modality, every action",
                "yes, all 7",
                f"beats for {sum(c == 'beats' for c in cats.values())}, matches for "
                f"{sum(c == 'matches' for c in cats.values())}, worse for {len(worse)} of {len(actions)}"
                f"{listed(worse)}",
                "agrees"
                if not worse
                else "differs: worse than the best single modality for " + ", ".join(worse),
                evidence=evidence,
            ),
            Headline(
                NAME,
                "which actions gain from combining (beats) and which only match",
                f"beats: {', '.join(PAPER['fig6_beats'])}; matches: {', '.join(PAPER['fig6_matches'])}",
                "; ".join(f"{a} {cats[a]}" for a in actions),
                "agrees: the same per action"
                if not mismatched
                else f"differs for {len(mismatched)} of {len([a for a in actions if a in paper_cat])}: {', '.join(mismatched)}",
                evidence=evidence,
            ),
        ]

    def body(self) -> list[str]:
        ctx, per_action = self.ctx, self.per_action
        return [
            f"{len(groups(ctx))} groups of {ctx.scale.fig6_group_size} objects × {ctx.scale.fig6_trials} trials per action "
            f"and model; {ctx.scale.fig6_budget} observations after the initial round (one per object), in random order. "
            '"Multi − best single": the accuracy difference to the single modality with the best mean curve, paired by '
            "run, averaged over the curve (95 % CI over groups); beats / matches / worse: the interval above / around / below 0.",
            "",
            markdown_table(
                [
                    "action",
                    "final accuracy per model",
                    "best single",
                    "Multi − best single (curve)",
                    "(last step)",
                    "verdict",
                ],
                [
                    [
                        a,
                        ", ".join(f"{k} {v:.3f}" for k, v in per_action[a]["final"].items()),
                        per_action[a]["best_single"],
                        ci(per_action[a]["vs_best"]),
                        ci(per_action[a]["vs_best_final"]),
                        self.cats[a],
                    ]
                    for a in self.actions
                ],
            ),
        ]

    def numbers(self) -> dict[str, Any]:
        return {
            a: {
                "best_single": d["best_single"],
                "mean_over_curve": d["overall"],
                "final": d["final"],
                "multi_vs_best": d["vs_best"].as_dict(),
                "multi_vs_best_final": d["vs_best_final"].as_dict(),
                "verdict": self.cats[a],
            }
            for a, d in self.per_action.items()
        }


analyse = _Fig6.analyse
