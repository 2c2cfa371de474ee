"""Fig. 7: transfer from 3 prior objects, all actions (paper §5.4).

``groups`` random groups of ``n_priors`` prior objects × ``trials`` trials; APTKT vs the
baseline (the paper's: nothing of the prior) on the same pool order and exploration draws, with
the control (the prior's feature space, no transfer) beside them. Small panels: each group's
mean curves; large panel: every run.
"""

from __future__ import annotations

import math
from typing import Any

from aptkt.experiments.figures.analysis import Analysis
from aptkt.experiments.figures.base import Context, Headline, Plan
from aptkt.experiments.figures.common import (
    GainSummary,
    accuracy_table,
    gain_summary,
    key_steps,
    method_curves,
    plot_panel,
    present,
    prior_group_plan,
    prior_groups,
    prior_space_rate,
    share_text,
    transfer_rate,
)
from aptkt.experiments.plots import canvas
from aptkt.experiments.report import PAPER, ci, gain_verdict, markdown_table, pp

NAME = "fig7"
TITLE = "transfer from 3 prior objects, all actions"
METHODS = ("baseline", "control", "APTKT")


def plan(ctx: Context) -> Plan:
    return prior_group_plan(ctx, NAME, ctx.scale.n_priors, METHODS, {"all": ctx.scale.actions})


class _Fig7(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        rows, where = self.rows, {"panel": "all"}
        self.methods = present(rows, METHODS)
        self.curves = method_curves(rows, where, self.methods)
        self.fused = method_curves(rows, where, self.methods, value="fused_accuracy")
        self.steps = steps = key_steps(self.ctx.scale.budget)
        self.gain = gain_summary(self.curves, "APTKT", steps=steps)
        self.fused_gain = gain_summary(self.fused, "APTKT", steps=steps)
        self.rate = transfer_rate(rows, {"method": "APTKT"})
        self.space_rate = prior_space_rate(rows, {"method": "APTKT"})
        self.groups = prior_groups(self.ctx, self.ctx.scale.n_priors)
        self.per_group = []
        self.group_curves = []
        for g, group in enumerate(self.groups):
            gc = method_curves(rows, {**where, "group": g}, self.methods)
            self.group_curves.append(gc)
            self.per_group.append((g, group, gain_summary(gc, "APTKT")))
        # The control beside APTKT: the prior's feature space alone, and the transfer on top.
        self.split = (
            (
                gain_summary(self.curves, "control", steps=steps),
                gain_summary(self.curves, "APTKT", base="control", steps=steps),
            )
            if "control" in self.curves
            else None
        )
        self.keep_curves({"panel": "all"}, self.curves)
        self.keep_curves({"panel": "all (fused)"}, self.fused)

    def draw(self) -> list[str]:
        ctx, groups = self.ctx, self.groups
        # Paper layout: one small panel per group (mean of its trials), a large one of all runs.
        ncols = math.ceil(len(groups) / 2)
        fig = canvas(figsize=(4.0 * ncols + 7, 6.4), layout="constrained")
        grid = fig.add_gridspec(2, ncols + 2)
        for g, group in enumerate(groups):
            ax = fig.add_subplot(grid[g // ncols, g % ncols])
            # Small panels keep short axis labels; the title names the group's priors.
            plot_panel(
                ax,
                self.group_curves[g],
                f"group {g}:\n" + ctx.names(group, sep=",\n"),
                chance=ctx.chance,
                xlabel="observations",
                ylabel="accuracy",
                legend=False,
            )
            ax.title.set_fontsize(8)
        big = fig.add_subplot(grid[:, ncols:])
        runs = self.curves["APTKT"].n_runs
        plot_panel(big, self.curves, f"average of {runs} runs", chance=ctx.chance)
        fig.suptitle(
            f"Fig. 7 — transfer from {ctx.scale.n_priors} prior objects, {len(ctx.scale.actions)} actions"
        )
        return self.write(fig)

    def headlines(self) -> list[Headline]:
        gain, n_priors = self.gain, self.ctx.scale.n_priors
        mean_gain = gain.gain.mean()
        return [
            Headline(
                NAME,
                f"transfer from {n_priors} priors: gain over the baseline throughout learning",
                pp(PAPER["fig7_gain"]),
                ci(gain.overall) + " (mean over steps)",
                gain_verdict(gain.overall, PAPER["fig7_gain"]),
                why=_decomposition_text(self.split),
            ),
            Headline(
                NAME,
                "APTKT above the baseline at every step",
                "yes (Fig. 7)",
                f"mean gain > 0 at {round(gain.positive_steps * len(mean_gain))} of {len(mean_gain)} steps "
                f"(smallest {pp(float(mean_gain.min()))}, largest {pp(float(mean_gain.max()))})",
                "agrees"
                if gain.positive_steps == 1.0
                else "differs: the mean gain is not positive at every step",
                evidence=[gain.overall],
            ),
        ]

    def body(self) -> list[str]:
        ctx, gain, fused_gain, steps = self.ctx, self.gain, self.fused_gain, self.steps
        s = ctx.scale
        return [
            f"{len(self.groups)} groups of {s.n_priors} priors × {s.trials} trials; budget {s.budget} "
            f"observations after the initial round of {len(s.actions) * len(s.new_objects)} "
            "(every action once on every new object). Accuracy: each action's model on its test observations, "
            "averaged over actions.",
            "",
            accuracy_table(self.curves, steps, self.fused),
            "",
            "Gain (APTKT − baseline), paired by run:",
            "",
            markdown_table(
                ["step", "gain", "fused over actions"],
                [[st, ci(gain.at[st]), ci(fused_gain.at[st])] for st in steps if st in gain.at]
                + [
                    ["mean over all steps", ci(gain.overall), ci(fused_gain.overall)],
                    [f"peak (step {gain.peak_step})", ci(gain.peak), ""],
                ],
            ),
            "",
            f"APTKT transferred a prior object in {100 * self.rate:.1f} % of its transfer decisions (ε_neg = {s.eps_neg}); "
            f"share of its models fitted in the prior's feature space: {share_text(self.space_rate, 1)}.",
            "",
            *_control_lines(self.curves, self.fused, steps),
            "",
            "Per group (gain = mean over steps of APTKT − baseline):",
            "",
            markdown_table(
                ["group", "priors", "gain"],
                [[g, ctx.names(group), ci(sm.overall)] for g, group, sm in self.per_group],
            ),
        ]

    def numbers(self) -> dict[str, Any]:
        split = self.split
        control: dict[str, Any] = (
            {"control_vs_baseline": split[0].as_dict(), "APTKT_vs_control": split[1].as_dict()}
            if split
            else {}
        )
        return {
            **control,
            "gain": self.gain.as_dict(),
            "fused_gain": self.fused_gain.as_dict(),
            "transfer_rate": self.rate,
            "prior_space_rate": self.space_rate,
            "per_group": {g: sm.overall.as_dict() for g, _, sm in self.per_group},
        }


analyse = _Fig7.analyse


def _control_lines(curves, fused, steps) -> list[str]:
    """The control beside the baseline: what the prior's feature space alone is worth, and what
    the transfer adds on top of it."""
    pairs = [
        (name, method, base)
        for name, method, base in (
            ("control − baseline (the prior's feature space alone)", "control", "baseline"),
            ("APTKT − control (the transfer alone)", "APTKT", "control"),
        )
        if method in curves and base in curves
    ]
    if not pairs:
        return []
    rows = []
    for name, method, base in pairs:
        g = gain_summary(curves, method, base=base, steps=steps)
        f = gain_summary(fused, method, base=base, steps=steps)
        rows.append([name, ci(g.at[0]) if 0 in g.at else "", ci(g.overall), ci(f.overall)])
    return [
        "Beyond the paper, paired by run: the control (the prior's feature space and kernel, no "
        "transfer):",
        "",
        markdown_table(["comparison", "step 0", "mean over all steps", "fused, all steps"], rows),
    ]


def _decomposition_text(split: tuple[GainSummary, GainSummary] | None) -> str:
    """APTKT's gain split into the prior's feature space alone (the control) and the transfer
    on top of it, over the curve — where the control was run."""
    if split is None:
        return ""
    space, transfer = (g.overall.mean for g in split)
    return (
        f"of the gain over the curve, the prior's feature space alone (the control: no transfer) "
        f"accounts for {pp(space)} and the transfer on top of it (APTKT − control) for "
        f"{pp(transfer)}"
    )
