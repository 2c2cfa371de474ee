"""The transfer heat-map's cells: short lines that fit a cell, a legend that matches the numbers
the command line prints."""

from __future__ import annotations

import numpy as np
import pytest

from aptkt.experiments.relatedness_plot import Relatedness, _cell_text, plot_relatedness
from aptkt.learning.config import LearnerConfig


def _matrix() -> Relatedness:
    m = Relatedness(["sponge", "box"], ["foam", "carton", "tile"], runs=3, stat="log odds")
    m.p[:] = [[0.8, 0.2, 0.3], [0.5, 0.61, 0.1]]
    m.transferred[0, 0], m.lam[0, 0] = 3, 0.8
    m.stopped[1, 1], m.log_bf[1, 1] = 2, -977.24
    m.stopped[1, 0], m.log_bf[1, 0] = 1, 2.44
    return m


@pytest.mark.parametrize(
    "cell, lines",
    [
        ((0, 0), ["0.80", "λ 0.80", "3/3"]),
        ((1, 1), ["0.61", "-977", "2/3"]),
        ((1, 0), ["0.50", "2.4", "1/3"]),
        ((0, 1), ["0.20"]),
    ],
)
def test_a_cell_holds_short_lines(cell, lines):
    """(The log odds and the run count on one line, 20 characters, ran into the next cell.)"""
    assert _cell_text(_matrix(), *cell).splitlines() == lines


def test_the_legend_names_the_bar_rather_than_only_the_margin(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    captured = {}
    real_savefig = Figure.savefig

    def keep(fig, *args, **kwargs):
        captured["legend"] = [t.get_text() for t in fig.legends[0].texts]
        return real_savefig(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    plot_relatedness({"P1": _matrix()}, tmp_path / "t", method="APTKT", config=LearnerConfig())
    stopped = [t for t in captured["legend"] if t.startswith("stopped by")]
    assert len(stopped) == 1 and "what the library's own objects reach" in stopped[0]
    assert "<= 3)" not in stopped[0]
    assert np.all([(tmp_path / f"t.{ext}").stat().st_size > 0 for ext in ("png", "svg")])
