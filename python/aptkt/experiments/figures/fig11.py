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
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt.experiments.figures import fig10
from aptkt.experiments.figures.base import (
    STRESS_CUTOFF,
    STRESS_NO_CUTOFF,
    Context,
    Headline,
    Plan,
    Section,
)
from aptkt.experiments.figures.common import (
    accuracy_table,
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
from aptkt.experiments.plots import figure
from aptkt.experiments.report import ci, listed, markdown_table, no_harm_verdict, pp, span
from aptkt.experiments.tables import curves_rows

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
            for m in STRESS_METHODS if panel == STRESS else METHODS:
                tags = {
                    "figure": NAME,
                    "panel": panel,
                    "group": 0,
                    "trial": t,
                    "priors": ",".join(task.objects),
                }
                plan.specs.append(
                    ctx.spec(
                        m,
                        ctx.learner(m, seed=seed),
                        actions,
                        ctx.scale.new_objects,
                        task,
                        seed,
                        tags,
                    )
                )
    return plan


def analyse(ctx: Context, rows: Sequence[Mapping[str, Any]]) -> Section:
    design = panels(ctx)
    steps = key_steps(ctx.scale.budget)
    keys = list(design)
    stress = [r for r in rows if r.get("panel") == STRESS]
    shown = keys + ([STRESS] if stress else [])
    ncols = min(4, len(shown))
    nrows = math.ceil(len(shown) / ncols)
    fig, axes = figure(nrows, ncols, figsize=(4.2 * ncols, 3.8 * nrows), squeeze=False)
    gains, rates, spaces, worst, curve_rows, tables = {}, {}, {}, {}, [], []
    control, control_worst, over_control, lambdas = {}, {}, {}, {}
    methods = present(rows, METHODS)  # the control runs in the settings only, never in stress
    for i, (ax, key) in enumerate(zip(axes.ravel(), keys)):
        curves = method_curves(rows, {"panel": key}, methods)
        gains[key] = gain_summary(curves, "APTKT", steps=steps)
        if "control" in curves:
            control[key] = gain_summary(curves, "control", steps=steps)
            control_worst[key] = float(np.nanmin(control[key].gain.mean()))
            over_control[key] = gain_summary(curves, "APTKT", base="control", steps=steps)
        rates[key] = transfer_rate(rows, {"method": "APTKT", "panel": key})
        lambdas[key] = mean_lambda(rows, {"method": "APTKT", "panel": key})
        spaces[key] = prior_space_rate(rows, {"method": "APTKT", "panel": key})
        worst[key] = float(np.nanmin(gains[key].gain.mean()))
        label = "all actions" if key == fig10.ALL else key
        plot_panel(
            ax,
            curves,
            f"{label}, priors:\n{ctx.names(design[key][1])}",
            chance=ctx.chance,
            legend=(i == 0),
        )
        curve_rows += [
            r for m, c in curves.items() for r in curves_rows({"panel": key, "method": m}, c)
        ]
        fused = (
            method_curves(rows, {"panel": key}, methods, value="fused_accuracy")
            if key == fig10.ALL
            else None  # one action: fused is the action's own accuracy
        )
        tables.append(f"**{label}**\n\n" + accuracy_table(curves, steps, fused))
    stress_numbers: dict[str, Any] = {}
    if stress:
        ax = axes.ravel()[len(keys)]
        methods = present(stress, STRESS_METHODS)
        curves = method_curves(stress, {}, methods)
        fused = method_curves(stress, {}, methods, value="fused_accuracy")
        plot_panel(
            ax,
            curves,
            f"stress: λ = 1 from the least related of\n{ctx.names(design[fig10.ALL][1])}",
            chance=ctx.chance,
        )
        curve_rows += [
            r for m, c in curves.items() for r in curves_rows({"panel": STRESS, "method": m}, c)
        ]
        tables.append("**stress (all actions)**\n\n" + accuracy_table(curves, steps, fused))
        for m in methods[1:]:
            g = gain_summary(curves, m, steps=steps)
            stress_numbers[m] = {
                "gain": g.as_dict(),
                "worst_step_gain": float(np.nanmin(g.gain.mean())),
                "transfer_rate": transfer_rate(stress, {"method": m}),
            }
    for ax in axes.ravel()[len(shown) :]:
        ax.set_visible(False)
    fig.suptitle("Fig. 11 — negative-transfer test: priors dissimilar to the new objects")
    fig.tight_layout()
    files = ctx.write_figure(NAME, fig, rows, curve_rows)

    harmed = [k for k in keys if gains[k].overall.significant_negative]
    harmed_early = [k for k in keys if 0 in gains[k].at and gains[k].at[0].significant_negative]
    headlines = [
        Headline(
            NAME,
            f"dissimilar priors: APTKT ≈ baseline (no negative transfer) in all {len(keys)} settings",
            "yes",
            f"significantly below the baseline over the curve in {len(harmed)} of {len(keys)} "
            f"{listed(harmed)}; at step 0 in {len(harmed_early)}{listed(harmed_early)}",
            "agrees: no negative transfer"
            if not harmed
            else "differs: negative transfer in " + ", ".join(harmed),
            evidence=[gains[k].overall for k in keys],
            why=_space_text(harmed, gains, control, over_control),
        )
    ]
    # The paper explains the absence of harm by the cut-off: "stopped transferring". We read
    # "stopped" as at most 20 % of APTKT's transfer decisions choosing a prior.
    stopped = [k for k in keys if rates[k] <= STOPPED]
    headlines.append(
        Headline(
            NAME,
            "with dissimilar priors APTKT stops transferring (λ under ε_neg)",
            "yes",
            f"transfer rate {span([100 * r for r in rates.values()])} of decisions "
            f"(at most {STOPPED * 100:.0f} % in {len(stopped)} of {len(keys)} settings)",
            "agrees"
            if len(stopped) == len(keys)
            else f"differs: APTKT kept transferring in {len(keys) - len(stopped)} of {len(keys)} settings — the absence of "
            "harm is not the cut-off's doing",
            why=_rate_text(ctx, [k for k in keys if k not in stopped], lambdas, over_control),
        )
    )
    below = [k for k in keys if worst[k] < -HARM]
    headlines.append(
        Headline(
            NAME,
            f"no step below the baseline by more than {100 * HARM:.0f} pp (mean over trials)",
            "yes (Fig. 11)",
            f"worst step {pp(min(worst.values()))}; more than {100 * HARM:.0f} pp below in "
            f"{len(below)} of {len(keys)} settings{listed(below)}",
            "agrees" if not below else "differs: " + ", ".join(below),
            evidence=[gains[k].overall for k in keys],
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
    )
    if STRESS_NO_CUTOFF in stress_numbers and STRESS_CUTOFF in stress_numbers:
        raw, cut = stress_numbers[STRESS_NO_CUTOFF], stress_numbers[STRESS_CUTOFF]
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
    body = [
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
                    ctx.names(design[k][1]),
                    ci(gains[k].overall),
                    no_harm_verdict(gains[k].overall),
                    ci(gains[k].at[0]) if 0 in gains[k].at else "",
                    pp(worst[k]),
                    f"{100 * rates[k]:.0f} %",
                    share_text(spaces[k]),
                    f"{ci(control[k].overall)} / {pp(control_worst[k])}" if k in control else "",
                ]
                for k in keys
            ],
        ),
        "",
        "\n\n".join(tables),
    ]
    numbers = {
        "gain": {k: g.as_dict() for k, g in gains.items()},
        "transfer_rate": rates,
        "prior_space_rate": spaces,
        "worst_step_gain": worst,
        "mean_lambda": lambdas,
        "control_vs_baseline": {k: g.as_dict() for k, g in control.items()},
        "control_worst_step_gain": control_worst,
        "APTKT_vs_control": {k: g.as_dict() for k, g in over_control.items()},
        "stress": stress_numbers,
        "priors": {k: list(v[1]) for k, v in design.items()},
    }
    return Section(NAME, TITLE, headlines, "\n".join(body), files, numbers)


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
