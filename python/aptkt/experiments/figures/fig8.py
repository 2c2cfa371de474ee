"""Fig. 8: transfer when learning with one exploratory action only (paper §5.4).

The design of Fig. 7 (same prior groups, same trial seeds), run once per action with only that
action: the initial round observes it once on every new object, then ``budget`` observations.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from aptkt.experiments.figures.analysis import Analysis, hide_unused, panel_grid
from aptkt.experiments.figures.base import Context, Headline, Plan
from aptkt.experiments.figures.common import (
    accuracy_table,
    error_removed,
    gain_summary,
    key_steps,
    method_curves,
    plot_panel,
    prior_group_plan,
    transfer_rate,
)
from aptkt.experiments.report import PAPER, ci, gain_verdict, listed, markdown_table, pp

NAME = "fig8"
TITLE = "transfer with one exploratory action at a time"
METHODS = ("baseline", "APTKT")
#: A gain is "little" (the paper's word for S1 and S4) below half the all-action gain of Fig. 7.
LITTLE = PAPER["fig7_gain"] / 2


def plan(ctx: Context) -> Plan:
    return prior_group_plan(
        ctx, NAME, ctx.scale.n_priors, METHODS, {a: (a,) for a in ctx.scale.actions}
    )


class _Fig8(Analysis):
    name, title = NAME, TITLE

    def measure(self) -> None:
        self.actions = list(self.ctx.scale.actions)
        self.steps = key_steps(self.ctx.scale.budget)
        self.curves, self.gains, self.removed, self.tables = {}, {}, {}, []
        for a in self.actions:
            curves = self.curves[a] = method_curves(self.rows, {"panel": a}, METHODS)
            gain = self.gains[a] = gain_summary(curves, "APTKT", steps=self.steps)
            self.removed[a] = {
                "curve": error_removed(curves["baseline"], gain.gain),
                "peak": error_removed(curves["baseline"], gain.gain, step=gain.peak_step),
            }
            self.keep_curves({"panel": a}, curves)
            self.tables.append(f"**{a}**\n\n" + accuracy_table(curves, self.steps))
        self.rates = {
            a: transfer_rate(self.rows, {"method": "APTKT", "panel": a}) for a in self.actions
        }

    def draw(self) -> list[str]:
        actions = self.actions
        fig, axes = panel_grid(len(actions) + 1)
        for i, a in enumerate(actions):
            plot_panel(axes[i], self.curves[a], a, chance=self.ctx.chance, legend=(i == 0))
        ax = axes[len(actions)]
        x = np.arange(len(actions))
        overall = [self.gains[a].overall for a in actions]
        peak = [self.gains[a].peak for a in actions]
        ax.bar(
            x - 0.2, [100 * e.mean for e in overall], 0.4, label="mean over steps", color="tab:blue"
        )
        ax.bar(
            x + 0.2, [100 * e.mean for e in peak], 0.4, label="at the best step", color="tab:cyan"
        )
        for xi, e in zip(x - 0.2, overall):
            if math.isfinite(e.low):
                ax.plot([xi, xi], [100 * e.low, 100 * e.high], color="k", lw=1)
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xticks(x, actions)
        ax.set_ylabel("APTKT − baseline (pp)")
        ax.set_title("gain per action")
        ax.legend(fontsize="small")
        hide_unused(axes, len(actions) + 1)
        fig.suptitle(
            f"Fig. 8 — transfer from {self.ctx.scale.n_priors} priors with one action at a time"
        )
        fig.tight_layout()
        return self.write(fig)

    def headlines(self) -> list[Headline]:
        gains, actions = self.gains, self.actions
        headlines = []
        if "P2" in gains:
            headlines.append(
                Headline(
                    NAME,
                    "P2 alone: gain over the baseline",
                    pp(PAPER["fig8_P2_gain"]) + " (at its best)",
                    f"{ci(gains['P2'].peak)} at step {gains['P2'].peak_step}; {ci(gains['P2'].overall)} over all steps",
                    gain_verdict(gains["P2"].peak, PAPER["fig8_P2_gain"]),
                    why=_room_text("P2", gains["P2"].peak_step, self.removed["P2"]),
                )
            )
        little = [a for a in PAPER["fig8_little"] if a in gains]
        if little:
            headlines.append(self._little(little))
        press = [a for a in PAPER["fig8_larger"] if a in gains]
        slide = [a for a in actions if a not in PAPER["fig8_larger"]]
        if press and slide:
            headlines.append(self._press_slide(press, slide))
        pos = [a for a in actions if gains[a].overall.significant_positive]
        neg = [a for a in actions if gains[a].overall.significant_negative]
        headlines.append(
            Headline(
                NAME,
                "APTKT above the baseline with every single action",
                f"yes, all {len(actions)}",
                f"significantly above for {len(pos)} of {len(actions)}{listed(pos)}; "
                f"significantly below for {len(neg)}{listed(neg)}",
                "agrees"
                if len(pos) == len(actions)
                else f"differs: {len(actions) - len(pos)} action(s) without a significant gain",
                evidence=[gains[a].overall for a in actions],
            )
        )
        return headlines

    def _little(self, little: list[str]) -> Headline:
        gains = self.gains
        small = all(gains[a].overall.mean < LITTLE for a in little)
        return Headline(
            NAME,
            f"{' and '.join(little)} alone: little gain (< {pp(LITTLE, sign=False)} over the curve)",
            "little",
            "; ".join(f"{a} {ci(gains[a].overall)}" for a in little),
            "agrees"
            if small
            else "differs: "
            + ", ".join(a for a in little if gains[a].overall.mean >= LITTLE)
            + f" gain(s) {pp(LITTLE, sign=False)} or more",
            evidence=[gains[a].overall for a in little],
        )

    def _press_slide(self, press: list[str], slide: list[str]) -> Headline:
        gains, removed = self.gains, self.removed
        mp = float(np.mean([gains[a].overall.mean for a in press]))
        ms = float(np.mean([gains[a].overall.mean for a in slide]))
        base_p, base_s = (
            float(np.mean([removed[a]["curve"][0] for a in group])) for group in (press, slide)
        )
        share_p, share_s = (
            float(np.mean([removed[a]["curve"][1] for a in group])) for group in (press, slide)
        )
        return Headline(
            NAME,
            f"pressing/static actions ({', '.join(press)}) gain more than sliding ({', '.join(slide)})",
            "yes",
            f"mean gain {pp(mp)} vs {pp(ms)}",
            "agrees" if mp > ms else "differs: the sliding actions gain as much or more",
            evidence=[gains[a].overall for a in press + slide],
            why=_press_slide_text(base_p, base_s, share_p, share_s),
        )

    def body(self) -> list[str]:
        s, gains, removed = self.ctx.scale, self.gains, self.removed
        return [
            f"Same prior groups and trial seeds as Fig. 7, one action per run; budget {s.budget} observations "
            f"after the initial round of {len(s.new_objects)}.",
            "",
            "The baseline's error removed: APTKT's mean gain divided by the error the baseline "
            "leaves (1 − its mean accuracy), over the curve and at the best step — the same "
            "transfer gains fewer pp where the baseline is already good.",
            "",
            markdown_table(
                [
                    "action",
                    "gain over all steps",
                    "gain at step 1",
                    "best step",
                    "gain there",
                    "baseline's error removed (curve / best step)",
                    "transfer rate",
                ],
                [
                    [
                        a,
                        ci(gains[a].overall),
                        ci(gains[a].at[1]) if 1 in gains[a].at else "",
                        gains[a].peak_step,
                        ci(gains[a].peak),
                        f"{_percent(removed[a]['curve'][1])} / {_percent(removed[a]['peak'][1])}",
                        f"{100 * self.rates[a]:.0f} %",
                    ]
                    for a in self.actions
                ],
            ),
            "",
            "Accuracy per action (mean ± sd over runs):",
            "",
            "\n\n".join(self.tables),
        ]

    def numbers(self) -> dict[str, Any]:
        return {
            "gain": {a: g.as_dict() for a, g in self.gains.items()},
            "transfer_rate": self.rates,
            "baseline_error_removed": {
                a: {k: {"baseline": v[0], "share": v[1]} for k, v in r.items()}
                for a, r in self.removed.items()
            },
        }


analyse = _Fig8.analyse


def _percent(share: float) -> str:
    return f"{100 * share:.0f} %" if math.isfinite(share) else "n/a (no error left)"


def _room_text(action: str, step: int, removed: Mapping[str, tuple[float, float]]) -> str:
    base, share = removed["peak"]
    return (
        f"the {action} baseline is at {base:.3f} at step {step}, so no method can gain more than "
        f"{pp(1 - base)} there; APTKT removes {_percent(share)} of the baseline's error at "
        f"that step and {_percent(removed['curve'][1])} over the curve"
    )


def _press_slide_text(base_p: float, base_s: float, share_p: float, share_s: float) -> str:
    higher = "pressing/static" if base_p > base_s else "sliding"
    return (
        f"the baselines' mean accuracy over the curve is {base_p:.3f} with the pressing/static "
        f"actions and {base_s:.3f} with the sliding ones, so a gain in pp has less room with "
        f"the {higher} ones; as a share of the baseline's error APTKT removes "
        f"{_percent(share_p)} with the pressing/static actions and {_percent(share_s)} with "
        "the sliding ones (mean over actions)"
    )
