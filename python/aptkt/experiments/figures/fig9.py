"""Fig. 9: more prior objects (3, 5, 7, 10); baseline vs APTKT vs APTKT with auxiliary
features (paper §5.5).

Per number of priors: ``groups`` random groups (every possible group when there are fewer,
e.g. the one group of all 10) × ``trials`` trials, all actions. The runs with 3 priors are
exactly Fig. 7's (same groups, same seeds), plus APTKT+aux.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from aptkt.experiments.figures.base import Context, Headline, Plan, Section
from aptkt.experiments.figures.common import (
    accuracy_table,
    error_removed,
    gain_summary,
    key_steps,
    mean_lambda,
    method_curves,
    plot_panel,
    present,
    prior_group_plan,
    prior_groups,
    transfer_rate,
)
from aptkt.experiments.plots import figure
from aptkt.experiments.report import PAPER, ci, gain_verdict, markdown_table, pp
from aptkt.experiments.tables import curves_rows

NAME = "fig9"
TITLE = "increasing the number of prior objects; auxiliary features"
METHODS = ("baseline", "APTKT", "APTKT+aux")


def plan(ctx: Context) -> Plan:
    plan = Plan()
    for n in ctx.scale.prior_counts:
        part = prior_group_plan(ctx, NAME, n, METHODS, {"all": ctx.scale.actions})
        plan.priors += part.priors
        plan.specs += part.specs
    return plan


def analyse(ctx: Context, rows: Sequence[Mapping[str, Any]]) -> Section:
    counts = list(ctx.scale.prior_counts)
    steps = key_steps(ctx.scale.budget)
    fig, axes = figure(1, len(counts), figsize=(4.6 * len(counts), 4.2), squeeze=False)
    plain, aux, aux_vs_plain, rates, curve_rows, tables = {}, {}, {}, {}, [], []
    lambdas, aux_room = {}, {}
    multi: dict[int, Any] = {}
    methods = present(rows, METHODS)
    for i, n in enumerate(counts):
        curves = method_curves(rows, {"n_priors": n}, methods)
        if "APTKT-multi" in curves:
            multi[n] = (
                gain_summary(curves, "APTKT-multi", base="APTKT", steps=steps),
                transfer_rate(rows, {"method": "APTKT-multi", "n_priors": n}),
            )
        plain[n] = gain_summary(curves, "APTKT", steps=steps)
        aux[n] = gain_summary(curves, "APTKT+aux", steps=steps)
        aux_vs_plain[n] = gain_summary(curves, "APTKT+aux", base="APTKT", steps=steps)
        rates[n] = transfer_rate(rows, {"method": "APTKT", "n_priors": n})
        lambdas[n] = mean_lambda(rows, {"method": "APTKT", "n_priors": n})
        aux_room[n] = error_removed(
            curves["baseline"], aux[n].gain, step=1 if 1 in aux[n].at else 0
        )
        groups = len(prior_groups(ctx, n))
        plot_panel(
            axes[0, i],
            curves,
            f"({'abcdefgh'[i % 8]}) {n} prior objects, {groups} group(s)",
            chance=ctx.chance,
            legend=(i == 0),
        )
        curve_rows += [
            r for m, c in curves.items() for r in curves_rows({"n_priors": n, "method": m}, c)
        ]
        fused = method_curves(rows, {"n_priors": n}, METHODS, value="fused_accuracy")
        tables.append(f"**{n} priors**\n\n" + accuracy_table(curves, steps, fused))
    fig.suptitle(
        "Fig. 9 — more prior objects: baseline (red), APTKT (blue), APTKT with auxiliary features (green)"
    )
    fig.tight_layout()
    files = ctx.write_figure(NAME, fig, rows, curve_rows)

    most, fewest = max(counts), min(counts)
    one = 1 if 1 in aux[most].at else 0
    headlines = [
        Headline(
            NAME,
            f"auxiliary features with {most} priors: gain over the baseline after one new observation",
            pp(PAPER["fig9_aux_gain_10_priors"]) + " (10 priors)",
            ci(aux[most].at[one])
            + f" (step {one}; the baseline is at {aux_room[most][0]:.3f} there, and APTKT+aux "
            f"removes {100 * aux_room[most][1]:.0f} % of its error)",
            gain_verdict(aux[most].at[one], PAPER["fig9_aux_gain_10_priors"]),
        )
    ]
    if len(counts) > 1:
        fades = plain[most].overall.mean < plain[fewest].overall.mean
        fewer = rates[most] < rates[fewest]
        headlines.append(
            Headline(
                NAME,
                "plain transfer fades as priors are added (λ falls under ε_neg)",
                "yes",
                f"gain {pp(plain[fewest].overall.mean)} with {fewest} → {pp(plain[most].overall.mean)} with {most} priors; "
                f"transfer rate {100 * rates[fewest]:.0f} % → {100 * rates[most]:.0f} %",
                "agrees"
                if fades and fewer
                else "differs: "
                + ("the gain does not shrink" if not fades else "the transfer rate does not fall"),
                evidence=[plain[fewest].overall, plain[most].overall],
                why=_fade_text(ctx, fewest, most, lambdas, rates),
            )
        )
        more = [n for n in counts if n > fewest]
        restored = [n for n in more if aux_vs_plain[n].overall.significant_positive]
        headlines.append(
            Headline(
                NAME,
                f"auxiliary features beat plain APTKT with {', '.join(map(str, more))} priors",
                "yes",
                "; ".join(f"{n}: {ci(aux_vs_plain[n].overall)}" for n in more),
                "agrees"
                if len(restored) == len(more)
                else f"differs: significantly better for {len(restored)} of {len(more)} prior counts",
                evidence=[aux_vs_plain[n].overall for n in more],
                why=(
                    "the auxiliary features were to restore a transfer that fades with more "
                    "priors; plain APTKT's gain over the baseline at step 0 is "
                    + ", ".join(
                        f"{pp(plain[n].at[0].mean)} with {n}" for n in counts if 0 in plain[n].at
                    )
                    + " priors"
                ),
            )
        )
    if multi:
        better = [n for n, (g, _) in multi.items() if g.overall.significant_positive]
        worse = [n for n, (g, _) in multi.items() if g.overall.significant_negative]
        headlines.append(
            Headline(
                NAME,
                "beyond the paper: transfer from every prior above ε_neg at once "
                '(transfer="multi") is at least as good as the paper\'s single most related prior',
                "not in the paper",
                "; ".join(f"{n}: {ci(g.overall)}" for n, (g, _) in multi.items())
                + " (APTKT-multi − APTKT over the curve, by number of priors)",
                (
                    "agrees: never significantly worse; "
                    + (
                        f"significantly better with {', '.join(map(str, better))} priors"
                        if better
                        else "no significant difference with any number of priors"
                    )
                )
                if not worse
                else "differs: significantly worse with "
                + ", ".join(map(str, worse))
                + " prior(s)",
                evidence=[g.overall for g, _ in multi.values()],
            )
        )
    body = [
        f"Groups per count: {', '.join(f'{n}: {len(prior_groups(ctx, n))}' for n in counts)}; "
        f"{ctx.scale.trials} trials each; budget {ctx.scale.budget}.",
        "",
        markdown_table(
            [
                "priors",
                "APTKT − baseline (all steps)",
                "APTKT+aux − baseline (all steps)",
                "APTKT+aux − baseline (step 1)",
                "APTKT+aux − APTKT (all steps)",
                "APTKT transfer rate",
            ],
            [
                [
                    n,
                    ci(plain[n].overall),
                    ci(aux[n].overall),
                    ci(aux[n].at[one]),
                    ci(aux_vs_plain[n].overall),
                    f"{100 * rates[n]:.0f} %",
                ]
                for n in counts
            ],
        ),
        "",
        *(
            [
                "Beyond the paper: transfer from every prior above ε_neg at once (APTKT-multi, "
                "one multi-source kernel) against the paper's single most related prior, paired "
                "by run:",
                "",
                markdown_table(
                    ["priors", "APTKT-multi − APTKT (all steps)", "step 0", "multi transfer rate"],
                    [
                        [
                            n,
                            ci(g.overall),
                            ci(g.at[0]) if 0 in g.at else "",
                            f"{100 * r:.0f} %",
                        ]
                        for n, (g, r) in multi.items()
                    ],
                ),
                "",
            ]
            if multi
            else []
        ),
        "\n\n".join(tables),
    ]
    numbers = {
        "multi_vs_APTKT": {n: g.as_dict() for n, (g, _) in multi.items()},
        "multi_transfer_rate": {n: r for n, (_, r) in multi.items()},
        "APTKT": {n: g.as_dict() for n, g in plain.items()},
        "APTKT+aux": {n: g.as_dict() for n, g in aux.items()},
        "aux_vs_APTKT": {n: g.as_dict() for n, g in aux_vs_plain.items()},
        "transfer_rate": rates,
        "mean_lambda": lambdas,
        "aux_baseline_error_removed": {
            n: {"baseline": b, "share": r} for n, (b, r) in aux_room.items()
        },
    }
    return Section(NAME, TITLE, headlines, "\n".join(body), files, numbers)


def _fade_text(
    ctx: Context,
    fewest: int,
    most: int,
    lambdas: Mapping[int, float],
    rates: Mapping[int, float],
) -> str:
    """What the transfers' λ did as priors were added, and which relatedness made it."""
    if not (math.isfinite(lambdas[fewest]) and math.isfinite(lambdas[most])):
        return ""  # nothing transferred, or runs stored before λ was counted
    text = (
        f"the transferred priors' λ = p̄ averages {lambdas[fewest]:.2f} with {fewest} and "
        f"{lambdas[most]:.2f} with {most} priors (ε_neg = {ctx.scale.eps_neg})"
    )
    if rates[most] >= rates[fewest]:
        text += (
            "; with more old objects there are more candidates, and one of them passes ε_neg "
            "as often or more"
        )
    text += (
        "; p̄ is each old object's own binary probability, which does not have to spread over "
        "the old objects as they are added, as a probability normalised over them does — the "
        "paper explains its fade by the old objects becoming harder to tell apart"
    )
    return text
