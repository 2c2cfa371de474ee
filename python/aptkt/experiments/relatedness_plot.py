"""The relatedness heat-map: per action, how much each new object is like each old one (Eq. 3's
mean probability p̄), with the old object it learned from marked — or the one a cut-off
stopped.

The input is the transfer decisions in force at the end of each run
(:func:`aptkt.learning.transfer_summary.final_decisions`); cells are means over runs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.experiments.plots import figure, save_figure
from aptkt.learning.config import LearnerConfig
from aptkt.learning.transfer_summary import (
    EVIDENCE_CUTOFF,
    TRANSFERS,
    by_pair,
    cutoff_words,
    verdict,
)

__all__ = ["Relatedness", "relatedness", "plot_relatedness", "SOURCE_EDGE", "STOPPED_EDGE"]

#: The outline (colour, line style, width) of a cell whose old object was transferred, and of
#: one the evidence stopped.
SOURCE_EDGE = ("tab:red", "-", 2.5)
STOPPED_EDGE = ("0.35", "--", 1.8)


class Relatedness:
    """One action's new × old matrix of mean p̄ over runs, and per cell how many runs
    transferred that old object (with their mean λ) or tested and stopped it (the mean of the
    cut-off's log odds or log Bayes factor, named ``stat``)."""

    def __init__(
        self, new: Sequence[str], old: Sequence[str], runs: int, stat: str = "log BF"
    ) -> None:
        self.new, self.old, self.runs, self.stat = list(new), list(old), runs, stat
        shape = (len(self.new), len(self.old))
        self.p = np.full(shape, np.nan)
        self.transferred = np.zeros(shape, dtype=int)
        self.stopped = np.zeros(shape, dtype=int)
        self.lam = np.full(shape, np.nan)
        self.log_bf = np.full(shape, np.nan)


def relatedness(
    runs: Sequence[Mapping[str, Mapping[str, Mapping[str, Any]]]], config: LearnerConfig
) -> dict[str, Relatedness]:
    """Per action, the matrix of the runs' final decisions (see :class:`Relatedness`)."""
    out = {}
    for action, objects in by_pair(runs).items():
        first = next(iter(objects.values()))[0]
        old = list(first["mean_posterior"])
        m = Relatedness(list(objects), old, len(runs), cutoff_words(config)[0])
        for i, decisions in enumerate(objects.values()):
            for k, o in enumerate(old):
                m.p[i, k] = np.mean([d["mean_posterior"].get(o, np.nan) for d in decisions])
            lams: dict[int, list[float]] = {}
            bfs: dict[int, list[float]] = {}
            for d in decisions:
                v = verdict(d, config)
                if v.candidate not in old:
                    continue
                k = old.index(v.candidate)
                if v.outcome == TRANSFERS:
                    m.transferred[i, k] += 1
                    lams.setdefault(k, []).append(v.lam)
                elif v.outcome == EVIDENCE_CUTOFF:
                    m.stopped[i, k] += 1
                if math.isfinite(v.log_bf):
                    bfs.setdefault(k, []).append(v.log_bf)
            for k, values in lams.items():
                m.lam[i, k] = float(np.mean(values))
            for k, values in bfs.items():
                m.log_bf[i, k] = float(np.mean(values))
        out[action] = m
    return out


def _cell_text(m: Relatedness, i: int, k: int) -> str:
    """p̄, then λ or the cut-off's number, then in how many runs, a short line each: a cell is
    about an inch wide, and "log odds -120.3 3/3" on one line ran into the next cell (the
    outline's legend says which number it is)."""
    lines = [f"{m.p[i, k]:.2f}"]
    if m.transferred[i, k]:
        lines += [f"λ {m.lam[i, k]:.2f}", _share(m, m.transferred[i, k]).strip()]
    elif m.stopped[i, k]:
        value = m.log_bf[i, k]
        lines += [f"{value:.0f}" if abs(value) >= 10 else f"{value:.1f}"]
        lines += [_share(m, m.stopped[i, k]).strip()]
    return "\n".join(line for line in lines if line)


def _share(m: Relatedness, n: int) -> str:
    return f" {n}/{m.runs}" if m.runs > 1 else ""


def plot_relatedness(
    matrices: Mapping[str, Relatedness], stem: Path, *, method: str, config: LearnerConfig
) -> list[Path]:
    """One panel per action: cells p̄ (mean over runs); a solid outline where the new object
    learned from that old object (λ, in how many runs), a dashed one where the second cut-off
    (same-object or evidence) stopped it (its log odds or log Bayes factor)."""
    from matplotlib.patches import Patch, Rectangle  # matplotlib only when plotting

    n = len(matrices)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    first = next(iter(matrices.values()))
    cell_w = 1.2 * max(len(first.old), 2)
    fig, axes = figure(
        rows,
        cols,
        figsize=(cols * cell_w + 2.5, rows * (0.7 * max(len(first.new), 2) + 2.0) + 0.8),
        squeeze=False,
        layout="constrained",
    )
    image = None
    for ax, (action, m) in zip(axes.flat, matrices.items()):
        image = ax.imshow(m.p, vmin=0, vmax=1, cmap="Blues")
        for i in range(len(m.new)):
            for k in range(len(m.old)):
                ax.text(
                    k,
                    i,
                    _cell_text(m, i, k),
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if m.p[i, k] > 0.6 else "black",
                )
                colour, ls, lw = SOURCE_EDGE if m.transferred[i, k] else STOPPED_EDGE
                if m.transferred[i, k] or m.stopped[i, k]:
                    ax.add_patch(
                        Rectangle(
                            (k - 0.47, i - 0.47), 0.94, 0.94, fill=False, ec=colour, ls=ls, lw=lw
                        )
                    )
        ax.set_xticks(
            range(len(m.old)),
            [o.replace("_", " ") for o in m.old],
            rotation=45,
            ha="right",
            fontsize=8,
        )
        ax.set_yticks(range(len(m.new)), [o.replace("_", " ") for o in m.new], fontsize=8)
        ax.set_title(action, fontsize=10)
    for ax in list(axes.flat)[n:]:
        ax.set_axis_off()
    if image is not None:
        fig.colorbar(
            image,
            ax=axes.ravel().tolist(),
            shrink=0.8,
            label="p̄ (Eq. 3): new like old",
        )
    handles = [
        Patch(
            fill=False,
            label="learned from (λ)",
            ec=SOURCE_EDGE[0],
            ls=SOURCE_EDGE[1],
            lw=SOURCE_EDGE[2],
        )
    ]
    if config.cutoff != "paper":
        stat, cutoff = cutoff_words(config)
        # The same-object cut-off's bar is the margin or, where higher, what the library's own
        # distinct objects reach: "<= 3" beside a printed "<= 3.34" read as a contradiction.
        bar = (
            f"at most the bar: {config.evidence_margin:g} or what the library's own objects reach"
            if config.cutoff == "same-object"
            else f"at most {config.evidence_margin:g}"
        )
        handles.append(
            Patch(
                fill=False,
                label=f"stopped by the {cutoff} (its {stat} in the cell, {bar})",
                ec=STOPPED_EDGE[0],
                ls=STOPPED_EDGE[1],
                lw=STOPPED_EDGE[2],
            )
        )
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize="small")
    runs = f"mean of {first.runs} runs" if first.runs > 1 else "one run"
    fig.suptitle(f"{method}: new objects (rows) × prior objects, at the end of the run ({runs})")
    return save_figure(fig, stem)
