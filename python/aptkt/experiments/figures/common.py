"""Analysis pieces the transfer figures (7, 8, 9, 11) share: curves per method, paired gains
over the baseline with intervals, transfer rates, and the learning-curve panels."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.experiments.aggregate import Curves, Estimate, collect, difference, estimate
from aptkt.experiments.figures.base import Plan
from aptkt.experiments.plots import learning_curves
from aptkt.experiments.priors import PriorTask
from aptkt.experiments.report import markdown_table
from aptkt.experiments.sampling import draw_groups

__all__ = [
    "GainSummary",
    "method_curves",
    "present",
    "gain_summary",
    "transfer_rate",
    "prior_space_rate",
    "share_text",
    "plot_panel",
    "error_removed",
    "mean_lambda",
]

XLABEL = "observations after the initial round"


def method_curves(
    rows: Sequence[Mapping[str, Any]],
    where: Mapping[str, Any],
    methods: Iterable[str],
    value: str = "mean_accuracy",
) -> dict[str, Curves]:
    return {m: collect(rows, {**where, "method": m}, value=value) for m in methods}


def present(rows: Iterable[Mapping[str, Any]], methods: Sequence[str]) -> tuple[str, ...]:
    """The methods that have result rows, in the given order (optional comparisons, such as
    the control, are analysed only when they were run)."""
    have = {r.get("method") for r in rows}
    return tuple(m for m in methods if m in have)


@dataclass
class GainSummary:
    """``method - baseline``, run by run: over the whole curve, at chosen steps, at its peak."""

    gain: Curves
    overall: Estimate  # per-run mean over every step
    at: dict[int, Estimate]  # at step s
    peak_step: int
    peak: Estimate  # at the step where the mean gain is largest
    positive_steps: float  # fraction of steps with a positive mean gain

    def as_dict(self) -> dict[str, Any]:
        return {
            "overall": self.overall.as_dict(),
            "at_step": {int(s): e.as_dict() for s, e in self.at.items()},
            "peak_step": self.peak_step,
            "peak": self.peak.as_dict(),
            "positive_steps": self.positive_steps,
            "mean_gain_per_step": [float(v) for v in self.gain.mean()],
        }


def gain_summary(
    curves: Mapping[str, Curves], method: str, base: str = "baseline", steps: Sequence[int] = ()
) -> GainSummary:
    g = difference(curves[method], curves[base])
    units = g.units(0)  # the first element of the run identity: the group
    at = {int(s): estimate(g.column(s), units) for s in steps if s in set(g.x.tolist())}
    mean = g.mean()
    k = int(np.nanargmax(mean))
    return GainSummary(
        gain=g,
        overall=estimate(g.run_means(), units),
        at=at,
        peak_step=int(g.x[k]),
        peak=estimate(g.values[:, k], units),
        positive_steps=float(np.mean(mean > 0)),
    )


def _share(
    rows: Iterable[Mapping[str, Any]], where: Mapping[str, Any], part: str, whole: str
) -> float:
    """Σ part / Σ whole over the rows matching ``where``; NaN when the rows count nothing."""
    total = counted = 0
    for r in rows:
        if all(r.get(k) == v for k, v in where.items()):
            total += int(r.get(whole, 0) or 0)
            counted += int(r.get(part, 0) or 0)
    return counted / total if total else float("nan")


def transfer_rate(rows: Iterable[Mapping[str, Any]], where: Mapping[str, Any]) -> float:
    """Share of the transfer decisions (Eq. 3, every step) that transferred a prior object."""
    return _share(rows, where, "transfers", "decisions")


def prior_space_rate(rows: Iterable[Mapping[str, Any]], where: Mapping[str, Any]) -> float:
    """Share of the model fits (every step) made in the prior's feature space; the others are
    in the new objects' own (or the pooled) space. NaN for rows without the counts."""
    return _share(rows, where, "prior_space", "updates")


def mean_lambda(rows: Iterable[Mapping[str, Any]], where: Mapping[str, Any]) -> float:
    """The mean λ over every source transferred (every step) in the rows matching ``where``;
    NaN when nothing was transferred."""
    total = weight = 0.0
    for r in rows:
        if all(r.get(k) == v for k, v in where.items()):
            n = int(r.get("sources", 0) or 0)
            if n:
                total += n * float(r["mean_lambda"])
                weight += n
    return total / weight if weight else float("nan")


def error_removed(baseline: Curves, gain: Curves, step: int | None = None) -> tuple[float, float]:
    """The baseline's mean accuracy (at ``step``, or averaged over the curve) and the share of
    its error, 1 − accuracy, that the mean of ``gain`` (a method − baseline, paired by run, as
    :class:`GainSummary` holds it) removes there.

    A gain in percentage points is bounded by the error the baseline leaves: the same transfer
    gains less where the baseline is already good. The share reads gains against that room.
    """
    if step is None:
        acc_b, mean_gain = float(np.mean(baseline.mean())), float(np.mean(gain.mean()))
    else:
        acc_b = float(baseline.mean()[int(np.flatnonzero(baseline.x == step)[0])])
        mean_gain = float(gain.mean()[int(np.flatnonzero(gain.x == step)[0])])
    error = 1.0 - acc_b
    return acc_b, mean_gain / error if error > 0 else float("nan")


def share_text(rate: float, digits: int = 0) -> str:
    """A share as "12 %"; "not recorded" where the rows lack the counts (runs stored by an
    aptkt that did not record them are reused as they are)."""
    return f"{100 * rate:.{digits}f} %" if np.isfinite(rate) else "not recorded"


def plot_panel(
    ax,
    curves: Mapping[str, Curves],
    title: str,
    *,
    chance: float,
    xlabel: str = XLABEL,
    ylabel: str = "accuracy on the test set",
    legend: bool = True,
) -> None:
    x = next(iter(curves.values())).x
    # matplotlib only when plotting: it is slow to import, and the backend is chosen first
    # (plots._pyplot).
    from matplotlib.ticker import MaxNLocator

    learning_curves(
        ax,
        {m: c.values for m, c in curves.items()},
        x,
        chance=chance,
        title=title,
        xlabel=xlabel,
        ylabel=ylabel,
    )
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    if not legend and ax.get_legend() is not None:
        ax.get_legend().remove()


def prior_groups(ctx, n_priors: int) -> list[tuple[str, ...]]:
    """The random groups of ``n_priors`` prior objects (the same for every figure that asks)."""

    return draw_groups(
        ctx.scale.priors, n_priors, ctx.scale.groups, ctx.seed_for("prior-groups", n_priors)
    )


def prior_group_plan(
    ctx, figure: str, n_priors: int, methods: Sequence[str], panels: Mapping[str, Sequence[str]]
):
    """Runs of ``methods`` for every group of ``n_priors`` priors × ``trials`` trials × panel
    (a panel names the actions learned). A trial's seed depends on (n_priors, group, trial)
    only, so all methods and panels of a trial see the same pool order and exploration draws,
    and figures sharing a design share its runs."""

    plan = Plan()
    for g, group in enumerate(prior_groups(ctx, n_priors)):
        task = ctx.prior_task(group)
        plan.priors.append(task)
        for t in range(ctx.scale.trials):
            seed = ctx.seed_for("trial", n_priors, g, t)
            for panel, actions in panels.items():
                tags = {
                    "figure": figure,
                    "panel": panel,
                    "n_priors": n_priors,
                    "group": g,
                    "run": t,
                    "priors": ",".join(group),
                }
                add_runs(ctx, plan, methods, actions, task, seed, tags)
    return plan


def add_runs(
    ctx,
    plan: Plan,
    methods: Sequence[str],
    actions: Sequence[str],
    task: PriorTask,
    seed: int,
    tags: Mapping[str, Any],
) -> None:
    """One trial of ``methods`` learning the new objects with ``actions`` and ``task``'s prior
    knowledge, all from the same ``seed`` (the same pool order and exploration draws)."""
    for m in methods:
        spec = ctx.spec(
            m, ctx.learner(m, seed=seed), actions, ctx.scale.new_objects, task, seed, tags
        )
        plan.specs.append(spec)


def accuracy_table(
    curves: Mapping[str, Curves],
    steps: Sequence[int],
    fused: Mapping[str, Curves] | None = None,
) -> str:
    """Markdown: mean ± sd accuracy per method at chosen steps — the per-action average and,
    with ``fused`` (runs over several actions), all actions' posteriors fused beside it."""

    steps = [s for s in steps if s in set(next(iter(curves.values())).x.tolist())]
    rows = []
    for m, c in curves.items():
        kinds = [("per-action average", c)] + ([("fused", fused[m])] if fused else [])
        for kind, cc in kinds:
            mean, sd = cc.mean(), cc.sd()
            idx = [int(np.flatnonzero(cc.x == s)[0]) for s in steps]
            rows.append([m, kind, cc.n_runs] + [f"{mean[i]:.3f} ± {sd[i]:.3f}" for i in idx])
    return markdown_table(
        ["method", "accuracy", "runs"] + [f"step {s} (mean ± sd)" for s in steps], rows
    )


def key_steps(budget: int) -> list[int]:
    return sorted({0, 1, budget // 4, budget // 2, budget} & set(range(budget + 1)))
