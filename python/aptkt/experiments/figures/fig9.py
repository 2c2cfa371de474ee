"""Fig. 9: more prior objects (3, 5, 7, 10); baseline vs APTKT vs APTKT with auxiliary
features (paper §5.5).

Per number of priors: ``groups`` random groups (every possible group when there are fewer,
e.g. the one group of all 10) × ``trials`` trials, all actions. The runs with 3 priors are
exactly Fig. 7's (same groups, same seeds), plus APTKT+aux.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from aptkt.experiments.figures.analysis import Analysis, panel_grid
from aptkt.experiments.figures.base import Context, Headline, Plan
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
from aptkt.experiments.report import PAPER, ci, gain_verdict, markdown_table, pp

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


class _Fig9(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        ctx, rows = self.ctx, self.rows
        self.counts = list(ctx.scale.prior_counts)
        self.steps = steps = key_steps(ctx.scale.budget)
        self.curves: dict[int, Any] = {}
        self.plain, self.aux, self.aux_vs_plain, self.rates, self.tables = {}, {}, {}, {}, []
        self.lambdas, self.aux_room = {}, {}
        methods = present(rows, METHODS)
        for n in self.counts:
            curves = self.curves[n] = method_curves(rows, {"n_priors": n}, methods)
            self.plain[n] = gain_summary(curves, "APTKT", steps=steps)
            aux = self.aux[n] = gain_summary(curves, "APTKT+aux", steps=steps)
            self.aux_vs_plain[n] = gain_summary(curves, "APTKT+aux", base="APTKT", steps=steps)
            self.rates[n] = transfer_rate(rows, {"method": "APTKT", "n_priors": n})
            self.lambdas[n] = mean_lambda(rows, {"method": "APTKT", "n_priors": n})
            self.aux_room[n] = error_removed(
                curves["baseline"], aux.gain, step=1 if 1 in aux.at else 0
            )
            self.keep_curves({"n_priors": n}, curves)
            fused = method_curves(rows, {"n_priors": n}, METHODS, value="fused_accuracy")
            self.tables.append(f"**{n} priors**\n\n" + accuracy_table(curves, steps, fused))
        self.most, self.fewest = max(self.counts), min(self.counts)
        self.one = 1 if 1 in self.aux[self.most].at else 0

    def draw(self) -> list[str]:
        counts = self.counts
        fig, axes = panel_grid(len(counts), per_row=len(counts), size=(4.6, 4.2))
        for i, n in enumerate(counts):
            groups = len(prior_groups(self.ctx, n))
            plot_panel(
                axes[i],
                self.curves[n],
                f"({'abcdefgh'[i % 8]}) {n} prior objects, {groups} group(s)",
                chance=self.ctx.chance,
                legend=(i == 0),
            )
        fig.suptitle(
            "Fig. 9 — more prior objects: baseline (red), APTKT (blue), APTKT with auxiliary features (green)"
        )
        fig.tight_layout()
        return self.write(fig)

    def headlines(self) -> list[Headline]:
        most, one, aux_room = self.most, self.one, self.aux_room
        headlines = [
            Headline(
                NAME,
                f"auxiliary features with {most} priors: gain over the baseline after one new observation",
                pp(PAPER["fig9_aux_gain_10_priors"]) + " (10 priors)",
                ci(self.aux[most].at[one])
                + f" (step {one}; the baseline is at {aux_room[most][0]:.3f} there, and APTKT+aux "
                f"removes {100 * aux_room[most][1]:.0f} % of its error)",
                gain_verdict(self.aux[most].at[one], PAPER["fig9_aux_gain_10_priors"]),
            )
        ]
        if len(self.counts) > 1:
            headlines += [self._fades(), self._aux_beats_plain()]
        return headlines

    def _fades(self) -> Headline:
        plain, rates, most, fewest = self.plain, self.rates, self.most, self.fewest
        fades = plain[most].overall.mean < plain[fewest].overall.mean
        fewer = rates[most] < rates[fewest]
        return Headline(
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
            why=_fade_text(self.ctx, fewest, most, self.lambdas, rates),
        )

    def _aux_beats_plain(self) -> Headline:
        counts, plain, aux_vs_plain = self.counts, self.plain, self.aux_vs_plain
        more = [n for n in counts if n > self.fewest]
        restored = [n for n in more if aux_vs_plain[n].overall.significant_positive]
        return Headline(
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

    def body(self) -> list[str]:
        ctx, counts = self.ctx, self.counts
        return [
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
                        ci(self.plain[n].overall),
                        ci(self.aux[n].overall),
                        ci(self.aux[n].at[self.one]),
                        ci(self.aux_vs_plain[n].overall),
                        f"{100 * self.rates[n]:.0f} %",
                    ]
                    for n in counts
                ],
            ),
            "",
            "\n\n".join(self.tables),
        ]

    def numbers(self) -> dict[str, Any]:
        return {
            "APTKT": {n: g.as_dict() for n, g in self.plain.items()},
            "APTKT+aux": {n: g.as_dict() for n, g in self.aux.items()},
            "aux_vs_APTKT": {n: g.as_dict() for n, g in self.aux_vs_plain.items()},
            "transfer_rate": self.rates,
            "mean_lambda": self.lambdas,
            "aux_baseline_error_removed": {
                n: {"baseline": b, "share": r} for n, (b, r) in self.aux_room.items()
            },
        }


analyse = _Fig9.analyse


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
