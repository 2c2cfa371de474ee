"""Fig. 11: negative-transfer test with the dissimilar priors found by Fig. 10 (paper §5.6).

Per action (that action only, its own dissimilar priors) and for all actions (the priors
dissimilar on average): APTKT vs the baseline, ``fig11_trials`` trials each (one prior group,
so the trials — pool orders and exploration draws — are the only variation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from aptkt.experiments.figures import fig10
from aptkt.experiments.figures.base import Context, Headline, Plan, Section
from aptkt.experiments.figures.common import (
    accuracy_table,
    gain_summary,
    key_steps,
    method_curves,
    plot_panel,
    transfer_rate,
)
from aptkt.experiments.plots import figure
from aptkt.experiments.report import ci, listed, markdown_table, no_harm_verdict, span
from aptkt.experiments.tables import curves_rows

NAME = "fig11"
TITLE = "negative-transfer test with dissimilar priors"
METHODS = ("baseline", "APTKT")
#: "Stopped transferring": fewer than this share of the transfer decisions chose a prior.
STOPPED = 0.5


def panels(ctx: Context) -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    """Panel -> (actions learned, prior objects)."""
    chosen = fig10.similarity(ctx)["dissimilar"]
    out = {a: ((a,), tuple(chosen[a])) for a in ctx.scale.actions}
    out[fig10.ALL] = (tuple(ctx.scale.actions), tuple(chosen[fig10.ALL]))
    return out


def plan(ctx: Context) -> Plan:
    plan = Plan()
    for panel, (actions, priors) in panels(ctx).items():
        task = ctx.prior_task(priors)
        plan.priors.append(task)
        for t in range(ctx.scale.fig11_trials):
            seed = ctx.seed_for("fig11", panel, t)
            for m in METHODS:
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
    ncols = min(4, len(keys))
    nrows = math.ceil(len(keys) / ncols)
    fig, axes = figure(nrows, ncols, figsize=(4.2 * ncols, 3.8 * nrows), squeeze=False)
    gains, rates, curve_rows, tables = {}, {}, [], []
    for i, (ax, key) in enumerate(zip(axes.ravel(), keys)):
        curves = method_curves(rows, {"panel": key}, METHODS)
        gains[key] = gain_summary(curves, "APTKT", steps=steps)
        rates[key] = transfer_rate(rows, {"method": "APTKT", "panel": key})
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
            method_curves(rows, {"panel": key}, METHODS, value="fused_accuracy")
            if key == fig10.ALL
            else None  # one action: fused is the action's own accuracy
        )
        tables.append(f"**{label}**\n\n" + accuracy_table(curves, steps, fused))
    for ax in axes.ravel()[len(keys) :]:
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
        )
    ]
    # The paper explains the absence of harm by the cut-off: "stopped transferring". We read
    # "stopped" as fewer than half of APTKT's transfer decisions choosing a prior.
    stopped = [k for k in keys if rates[k] < STOPPED]
    headlines.append(
        Headline(
            NAME,
            "with dissimilar priors APTKT stops transferring (λ under ε_neg)",
            "yes",
            f"transfer rate {span([100 * r for r in rates.values()])} of decisions "
            f"(below {STOPPED * 100:.0f} % in {len(stopped)} of {len(keys)} settings)",
            "agrees"
            if len(stopped) == len(keys)
            else f"differs: APTKT kept transferring in {len(keys) - len(stopped)} of {len(keys)} settings — the absence of "
            "harm is not the cut-off's doing",
        )
    )
    body = [
        f"{ctx.scale.fig11_trials} trials per setting; budget {ctx.scale.budget}.",
        "",
        markdown_table(
            [
                "setting",
                "priors",
                "gain over all steps",
                "verdict",
                "gain at step 0",
                "transfer rate",
            ],
            [
                [
                    k,
                    ctx.numbers(design[k][1]),
                    ci(gains[k].overall),
                    no_harm_verdict(gains[k].overall),
                    ci(gains[k].at[0]) if 0 in gains[k].at else "",
                    f"{100 * rates[k]:.0f} %",
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
        "priors": {k: list(v[1]) for k, v in design.items()},
    }
    return Section(NAME, TITLE, headlines, "\n".join(body), files, numbers)
