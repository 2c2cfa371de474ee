"""Fig. 11: negative-transfer test with the dissimilar priors found by Fig. 10 (paper §5.6).

Per action (that action only, its own dissimilar priors) and for all actions (the priors
dissimilar on average): APTKT vs the baseline, ``fig11_trials`` trials each (one prior group,
so the trials — pool orders and exploration draws — are the only variation).

Beside them, the control (beyond the paper): the prior's feature space without any transfer,
which separates what the prior's transforms do to the new objects from what the transfers do.

Stress panel (beyond the paper): on the all-actions setting, transfer with λ forced to 1 from
the *least* related prior, without the cut-off (ε_neg = 0) and with it, beside the baseline and
APTKT — the harm that transfer with teeth does from an irrelevant prior, and whether the
cut-off prevents it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from aptkt.experiments.figures import fig10
from aptkt.experiments.figures.analysis import Analysis, hide_unused, panel_grid
from aptkt.experiments.figures.base import (
    STRESS_CUTOFF,
    STRESS_NO_CUTOFF,
    Context,
    Headline,
    Plan,
)
from aptkt.experiments.figures.common import (
    GainSummary,
    accuracy_table,
    add_runs,
    gain_summary,
    key_steps,
    mean_lambda,
    method_curves,
    plot_panel,
    present,
    prior_space_rate,
    share_text,
    transfer_rate,
)
from aptkt.experiments.report import ci, listed, markdown_table, no_harm_verdict, pp, span

NAME = "fig11"
TITLE = "negative-transfer test with dissimilar priors"
METHODS = ("baseline", "control", "APTKT")
STRESS = "stress"
STRESS_METHODS = ("baseline", "APTKT", STRESS_NO_CUTOFF, STRESS_CUTOFF)
#: "Stopped transferring": at most this share of the transfer decisions chose a prior.
STOPPED = 0.2
#: "No harm": no step's mean accuracy below the baseline's by more than this.
HARM = 0.02


def panels(ctx: Context) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    """Panel -> (actions learned, prior objects)."""
    chosen = fig10.similarity(ctx)["dissimilar"]
    out: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
        a: ((a,), tuple(chosen[a])) for a in ctx.scale.actions
    }
    out[fig10.ALL] = (tuple(ctx.scale.actions), tuple(chosen[fig10.ALL]))
    return out


def plan(ctx: Context) -> Plan:
    plan = Plan()
    design = panels(ctx)
    design[STRESS] = design[fig10.ALL]
    for panel, (actions, priors) in design.items():
        task = ctx.prior_task(priors)
        if panel != STRESS:
            plan.priors.append(task)
        # The stress panel shares the all-actions trials (seeds): its baseline and APTKT runs
        # are those of that setting, stored once.
        key = fig10.ALL if panel == STRESS else panel
        for t in range(ctx.scale.fig11_trials):
            seed = ctx.seed_for("fig11", key, t)
            methods = STRESS_METHODS if panel == STRESS else METHODS
            tags = {
                "figure": NAME,
                "panel": panel,
                "group": 0,
                "run": t,
                "priors": ",".join(task.objects),
            }
            add_runs(ctx, plan, methods, actions, task, seed, tags)
    return plan


class _Fig11(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        self.design = panels(self.ctx)
        self.steps = key_steps(self.ctx.scale.budget)
        self.keys = list(self.design)
        self.curves: dict[str, Any] = {}
        self.gains: dict[str, GainSummary] = {}
        self.control: dict[str, GainSummary] = {}  # control − baseline
        self.over_control: dict[str, GainSummary] = {}  # APTKT − control
        self.rates: dict[str, float] = {}
        self.spaces: dict[str, float] = {}
        self.lambdas: dict[str, float] = {}
        self.worst: dict[str, float] = {}  # the worst step's mean gain
        self.control_worst: dict[str, float] = {}
        self.tables: list[str] = []
        methods = present(self.rows, METHODS)  # the control runs in the settings only
        for key in self.keys:
            self._setting(key, methods)
        self.stress = [r for r in self.rows if r.get("panel") == STRESS]
        self.stress_numbers: dict[str, Any] = {}
        if self.stress:
            self._stress()

    def _setting(self, key: str, methods: tuple[str, ...]) -> None:
        rows, steps, where = self.rows, self.steps, {"method": "APTKT", "panel": key}
        curves = self.curves[key] = method_curves(rows, {"panel": key}, methods)
        gain = self.gains[key] = gain_summary(curves, "APTKT", steps=steps)
        if "control" in curves:
            self.control[key] = gain_summary(curves, "control", steps=steps)
            self.control_worst[key] = float(np.nanmin(self.control[key].gain.mean()))
            self.over_control[key] = gain_summary(curves, "APTKT", base="control", steps=steps)
        self.rates[key] = transfer_rate(rows, where)
        self.lambdas[key] = mean_lambda(rows, where)
        self.spaces[key] = prior_space_rate(rows, where)
        self.worst[key] = float(np.nanmin(gain.gain.mean()))
        self.keep_curves({"panel": key}, curves)
        fused = (
            method_curves(rows, {"panel": key}, methods, value="fused_accuracy")
            if key == fig10.ALL
            else None  # one action: fused is the action's own accuracy
        )
        table = accuracy_table(curves, steps, fused)
        self.tables.append(f"**{_label(key)}**\n\n" + table)

    def _stress(self) -> None:
        stress, steps = self.stress, self.steps
        methods = present(stress, STRESS_METHODS)
        curves = self.curves[STRESS] = method_curves(stress, {}, methods)
        fused = method_curves(stress, {}, methods, value="fused_accuracy")
        self.keep_curves({"panel": STRESS}, curves)
        self.tables.append("**stress (all actions)**\n\n" + accuracy_table(curves, steps, fused))
        for m in methods[1:]:
            g = gain_summary(curves, m, steps=steps)
            self.stress_numbers[m] = {
                "gain": g.as_dict(),
                "worst_step_gain": float(np.nanmin(g.gain.mean())),
                "transfer_rate": transfer_rate(stress, {"method": m}),
            }

    def draw(self) -> list[str]:
        ctx, design = self.ctx, self.design
        shown = self.keys + ([STRESS] if self.stress else [])
        fig, axes = panel_grid(len(shown))
        for i, (ax, key) in enumerate(zip(axes, self.keys)):
            title = f"{_label(key)}, priors:\n{ctx.names(design[key][1])}"
            plot_panel(ax, self.curves[key], title, chance=ctx.chance, legend=(i == 0))
        if self.stress:
            title = f"stress: λ = 1 from the least related of\n{ctx.names(design[fig10.ALL][1])}"
            plot_panel(axes[len(self.keys)], self.curves[STRESS], title, chance=ctx.chance)
        hide_unused(axes, len(shown))
        fig.suptitle("Fig. 11 — negative-transfer test: priors dissimilar to the new objects")
        fig.tight_layout()
        return self.write(fig)

    def headlines(self) -> list[Headline]:
        headlines = [self._no_harm(), self._stopped(), self._worst_step()]
        raw = self.stress_numbers.get(STRESS_NO_CUTOFF)
        cut = self.stress_numbers.get(STRESS_CUTOFF)
        if raw is not None and cut is not None:
            headlines.append(
                Headline(
                    NAME,
                    "stress (beyond the paper): λ = 1 from the least related prior; the cut-off "
                    "prevents the harm",
                    "not in the paper",
                    f"without the cut-off {pp(raw['gain']['overall']['mean'])} over the curve "
                    f"(worst step {pp(raw['worst_step_gain'])}, transfer rate "
                    f"{100 * raw['transfer_rate']:.0f} %); with it {pp(cut['gain']['overall']['mean'])} "
                    f"(worst step {pp(cut['worst_step_gain'])}, transfer rate {100 * cut['transfer_rate']:.0f} %)",
                    "agrees: the cut-off stops the harmful transfer"
                    if cut["worst_step_gain"] >= -HARM
                    else "differs: harm remains with the cut-off",
                )
            )
        return headlines

    def _no_harm(self) -> Headline:
        keys, gains = self.keys, self.gains
        harmed = [k for k in keys if gains[k].overall.significant_negative]
        harmed_early = [k for k in keys if 0 in gains[k].at and gains[k].at[0].significant_negative]
        return Headline(
            NAME,
            f"dissimilar priors: APTKT ≈ baseline (no negative transfer) in all {len(keys)} settings",
            "yes",
            f"significantly below the baseline over the curve in {len(harmed)} of {len(keys)} "
            f"{listed(harmed)}; at step 0 in {len(harmed_early)}{listed(harmed_early)}",
            "agrees: no negative transfer"
            if not harmed
            else "differs: negative transfer in " + ", ".join(harmed),
            evidence=[gains[k].overall for k in keys],
            why=_space_text(harmed, gains, self.control, self.over_control),
        )

    def _stopped(self) -> Headline:
        # The paper explains the absence of harm by the cut-off: "stopped transferring". We
        # read "stopped" as at most 20 % of APTKT's transfer decisions choosing a prior.
        keys, rates = self.keys, self.rates
        stopped = [k for k in keys if rates[k] <= STOPPED]
        return Headline(
            NAME,
            "with dissimilar priors APTKT stops transferring (λ under ε_neg)",
            "yes",
            f"transfer rate {span([100 * r for r in rates.values()])} of decisions "
            f"(at most {STOPPED * 100:.0f} % in {len(stopped)} of {len(keys)} settings)",
            "agrees"
            if len(stopped) == len(keys)
            else f"differs: APTKT kept transferring in {len(keys) - len(stopped)} of {len(keys)} settings — the absence of "
            "harm is not the cut-off's doing",
            why=_rate_text(
                self.ctx, [k for k in keys if k not in stopped], self.lambdas, self.over_control
            ),
        )

    def _worst_step(self) -> Headline:
        keys, worst, control_worst = self.keys, self.worst, self.control_worst
        below = [k for k in keys if worst[k] < -HARM]
        return Headline(
            NAME,
            f"no step below the baseline by more than {100 * HARM:.0f} pp (mean over trials)",
            "yes (Fig. 11)",
            f"worst step {pp(min(worst.values()))}; more than {100 * HARM:.0f} pp below in "
            f"{len(below)} of {len(keys)} settings{listed(below)}",
            "agrees" if not below else "differs: " + ", ".join(below),
            evidence=[self.gains[k].overall for k in keys],
            why=(
                "the control's (the prior's feature space, no transfer) worst step: "
                + "; ".join(
                    f"{k} {pp(control_worst[k])} (APTKT's {pp(worst[k])})"
                    for k in below
                    if k in control_worst
                )
                if any(k in control_worst for k in below)
                else ""
            ),
        )

    def body(self) -> list[str]:
        ctx, gains, control = self.ctx, self.gains, self.control
        return [
            f"{ctx.scale.fig11_trials} trials per setting; budget {ctx.scale.budget}. The control "
            "learns the new objects in the prior's feature space without any transfer: "
            "control − baseline is what the prior's transforms alone do to them.",
            "",
            markdown_table(
                [
                    "setting",
                    "priors",
                    "gain over all steps",
                    "verdict",
                    "gain at step 0",
                    "worst step",
                    "transfer rate",
                    "models in the prior's space",
                    "control − baseline (curve / worst step)",
                ],
                [
                    [
                        k,
                        ctx.names(self.design[k][1]),
                        ci(gains[k].overall),
                        no_harm_verdict(gains[k].overall),
                        ci(gains[k].at[0]) if 0 in gains[k].at else "",
                        pp(self.worst[k]),
                        f"{100 * self.rates[k]:.0f} %",
                        share_text(self.spaces[k]),
                        f"{ci(control[k].overall)} / {pp(self.control_worst[k])}"
                        if k in control
                        else "",
                    ]
                    for k in self.keys
                ],
            ),
            "",
            "\n\n".join(self.tables),
        ]

    def numbers(self) -> dict[str, Any]:
        return {
            "gain": {k: g.as_dict() for k, g in self.gains.items()},
            "transfer_rate": self.rates,
            "prior_space_rate": self.spaces,
            "worst_step_gain": self.worst,
            "mean_lambda": self.lambdas,
            "control_vs_baseline": {k: g.as_dict() for k, g in self.control.items()},
            "control_worst_step_gain": self.control_worst,
            "APTKT_vs_control": {k: g.as_dict() for k, g in self.over_control.items()},
            "stress": self.stress_numbers,
            "priors": {k: list(v[1]) for k, v in self.design.items()},
        }


analyse = _Fig11.analyse


def _label(key: str) -> str:
    return "all actions" if key == fig10.ALL else key


def _space_text(harmed, gains, control, over_control) -> str:
    """Where APTKT is below the baseline: how far the prior's feature space alone (the control)
    is below it, beside APTKT."""
    shown = [k for k in harmed if k in control]
    if not shown:
        return ""
    alone = [k for k in shown if control[k].overall.mean <= gains[k].overall.mean]
    return (
        "over the curve, against the baseline, the control (the prior's feature space without "
        "any transfer) and APTKT: "
        + "; ".join(
            f"{k} {pp(control[k].overall.mean)} and {pp(gains[k].overall.mean)}" for k in shown
        )
        + f" — in {len(alone)} of {len(shown)} the prior's space alone is at least as far below "
        "the baseline as APTKT"
    )


def _rate_text(ctx: Context, kept: Sequence[str], lambdas, over_control) -> str:
    """Why the transfers went on: how strongly the old classifiers claimed the new objects, and
    whether APTKT beat the same space without transfer."""
    lams = [lambdas[k] for k in kept if math.isfinite(lambdas[k])]
    if not lams:
        return ""
    config = ctx.learner("APTKT")
    text = (
        f"in the settings that kept transferring the transferred priors' λ = p̄ averaged "
        f"{span(lams, '{:.2f}', '')} (ε_neg = {ctx.scale.eps_neg}): the old objects' own "
        "classifiers claimed the new objects' observations"
    )
    if config.cutoff == "evidence":
        text += ", and the new objects' labels favoured the coupling (the evidence cut-off)"
    compared = [k for k in kept if k in over_control]
    if compared:
        beats = [k for k in compared if over_control[k].overall.mean > 0]
        text += (
            f"; APTKT is above the control (the prior's space without transfer) over the curve "
            f"in {len(beats)} of the {len(compared)} of them"
        )
        if 2 * len(beats) > len(compared):
            text += ": there, the transfers from these priors helped more often than not"
            if config.cutoff == "evidence":
                text += (
                    ", and a cut-off that judges by the new labels had little reason to stop them"
                )
    return text
