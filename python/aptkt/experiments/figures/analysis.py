"""The skeleton every figure's analysis follows (:class:`Analysis`): measure the runs' result
rows, draw the figure and write its files, then the report section — the headlines (the
paper's claims beside our numbers), the body and the numbers — and the pieces the figures'
drawings share (a grid of panels, the curves kept for ``curves.csv``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from aptkt.experiments.aggregate import Curves
from aptkt.experiments.figures.base import Context, Headline, Section
from aptkt.experiments.plots import figure
from aptkt.experiments.tables import curves_rows

__all__ = ["Analysis", "panel_grid", "hide_unused"]


class Analysis:
    """One figure's analysis of its runs' result rows. A figure sets :attr:`name` and
    :attr:`title` and fills in the steps; :meth:`section` runs them in order."""

    name: str
    title: str

    def __init__(self, ctx: Context, rows: Sequence[Mapping[str, Any]]):
        self.ctx = ctx
        self.rows = rows
        #: The curves the figure shows, one row per (panel, method, x): ``curves.csv``.
        self.curve_rows: list[dict[str, Any]] = []

    @classmethod
    def analyse(cls, ctx: Context, rows: Sequence[Mapping[str, Any]]) -> Section:
        """The figure's report section from its runs' result rows (a figure module's
        ``analyse``)."""
        return cls(ctx, rows).section()

    def section(self) -> Section:
        self.measure()
        files = self.draw()
        return Section(
            self.name,
            self.title,
            self.headlines(),
            "\n".join(self.body()),
            files,
            self.numbers(),
        )

    # -- the steps -------------------------------------------------------------------------
    def measure(self) -> None:
        """Curves, gains and rates from the rows, kept on the analysis."""
        raise NotImplementedError

    def draw(self) -> list[str]:
        """The figure and its files (relative to the output directory)."""
        raise NotImplementedError

    def headlines(self) -> list[Headline]:
        raise NotImplementedError

    def body(self) -> list[str]:
        """The section's Markdown, line by line."""
        raise NotImplementedError

    def numbers(self) -> dict[str, Any]:
        """The computed numbers (summary.json, tests)."""
        raise NotImplementedError

    # -- shared pieces ---------------------------------------------------------------------
    def keep_curves(self, tags: Mapping[str, Any], curves: Mapping[str, Curves]) -> None:
        """Keep each method's curve for ``curves.csv``, labelled with ``tags``."""
        self.curve_rows += [
            r for m, c in curves.items() for r in curves_rows({**tags, "method": m}, c)
        ]

    def write(self, fig: Any) -> list[str]:
        """The plot, every step of every run and the curves, in the figure's directory."""
        return self.ctx.write_figure(self.name, fig, self.rows, self.curve_rows)


def panel_grid(
    n: int,
    *,
    per_row: int = 4,
    size: tuple[float, float] = (4.2, 3.8),
    extra_width: float = 0.0,
    **kw: Any,
) -> tuple[Any, list[Any]]:
    """A figure of ``n`` panels, at most ``per_row`` a row, each ``size`` inches: the figure
    and its axes in reading order."""
    ncols = min(per_row, n)
    nrows = math.ceil(n / ncols)
    fig, axes = figure(
        nrows,
        ncols,
        figsize=(size[0] * ncols + extra_width, size[1] * nrows),
        squeeze=False,
        **kw,
    )
    return fig, list(axes.ravel())


def hide_unused(axes: Sequence[Any], used: int) -> None:
    """Hide the grid's panels after the first ``used``."""
    for ax in axes[used:]:
        ax.set_visible(False)
