"""Accuracy curves a reader can tell apart: every method its own line style and marker, each
later curve thinner so that equal curves both stay visible, bands inside [0, 1], and one panel
where one action makes the fused accuracy the same curve. One style serves every such plot:
the demo's and a table's learning curves, the reproduction's figures and the benchmark."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from matplotlib.colors import to_rgba

from aptkt.experiments import benchmark_report, demo
from aptkt.experiments.aggregate import Curves
from aptkt.experiments.figures.common import plot_panel
from aptkt.experiments.plots import curve_styles, figure, learning_curves
from aptkt.learning import APTKT, LearnerConfig, Observations, PoolEnvironment, PriorKnowledge

METHODS = ("APTKT", "APTKT+aux", "baseline")


def _method_lines(ax, methods):
    """The curve of each method (its legend label starts with the method's name)."""
    lines = {}
    for line in ax.get_lines():
        name = str(line.get_label()).split(" (n=")[0]
        if name in methods:
            lines[name] = line
    assert set(lines) == set(methods), [ln.get_label() for ln in ax.get_lines()]
    return lines


def _distinct_and_nested(lines):
    """Every method its own (line style, marker); in drawing order, each later line thinner."""
    looks = {(ln.get_linestyle(), ln.get_marker()) for ln in lines.values()}
    assert len(looks) == len(lines)
    assert len({ln.get_marker() for ln in lines.values()}) == len(lines)
    widths = [ln.get_linewidth() for ln in lines.values()]  # Axes keep the drawing order
    drawn = sorted(lines.values(), key=lambda ln: ln.zorder * 1000 + ln.axes.lines.index(ln))
    assert [ln.get_linewidth() for ln in drawn] == sorted(widths, reverse=True)
    assert len(set(widths)) == len(widths)


def test_equal_curves_stay_visible_and_distinct():
    same = np.tile(np.linspace(0.6, 1.0, 7), (3, 1))
    fig, ax = figure(1, 1)
    learning_curves(ax, {m: same for m in METHODS}, np.arange(7), chance=1 / 3)
    lines = _method_lines(ax, METHODS)
    _distinct_and_nested(lines)
    # The later lines are broken and their markers hollow: the earlier one shows through.
    first = max(lines.values(), key=lambda ln: ln.get_linewidth())
    for line in lines.values():
        if line is not first:
            assert line.get_linestyle() != "-"
            assert to_rgba(line.get_markerfacecolor())[3] == 0


def test_bands_stay_within_zero_and_one():
    runs = np.array([[1.0, 1.0, 0.2], [0.4, 1.0, 0.0], [1.0, 0.5, 0.1]])  # wide t intervals
    fig, ax = figure(1, 1)
    learning_curves(ax, {"APTKT": runs, "baseline": 1 - runs}, np.arange(3), chance=0.5)
    assert len(ax.collections) == 2
    for band in ax.collections:
        ys = np.concatenate([p.vertices[:, 1] for p in band.get_paths()])
        assert ys.min() >= 0.0 and ys.max() <= 1.0


def test_the_reproduction_figures_use_the_shared_style():
    same = np.tile(np.linspace(0.5, 0.9, 5), (4, 1))
    fig, ax = figure(1, 1)
    runs = [(r,) for r in range(4)]
    curves = {m: Curves(np.arange(5), same, runs) for m in ("baseline", "control", "APTKT")}
    plot_panel(ax, curves, "P2", chance=0.2)
    lines = _method_lines(ax, curves)
    _distinct_and_nested(lines)
    styles = curve_styles(curves, 5)
    for method, line in lines.items():
        assert line.get_linewidth() == pytest.approx(styles[method]["lw"])


def test_the_benchmark_plot_uses_the_shared_style():
    rng = np.random.default_rng(0)
    base = rng.uniform(0.5, 1.0, size=(6, 5))
    # (APTKT+aux a hair apart: a copy of APTKT is left out of the plot as adding nothing.)
    aux = base + 1e-3
    c = {3: {"random": {"baseline": base, "control": base, "APTKT": base, "APTKT+aux": aux}}}
    fig = benchmark_report.plot(c, chance=0.2)
    top = fig.axes[0]
    methods = ("baseline", "control", "APTKT", "APTKT+aux")
    lines = {ln.get_label(): ln for ln in top.get_lines() if ln.get_label() in methods}
    assert set(lines) == set(methods)
    _distinct_and_nested(lines)
    styles = curve_styles(methods, 5)
    for method, line in lines.items():
        assert line.get_marker() == styles[method]["marker"]
        assert line.get_linewidth() == pytest.approx(styles[method]["lw"])
    for band in top.collections:
        ys = np.concatenate([p.vertices[:, 1] for p in band.get_paths()])
        assert ys.min() >= 0.0 and ys.max() <= 1.0


def _rows(actions):
    """Step rows of real runs of each method on a small synthetic world."""
    from aptkt.experiments.runs import step_rows

    rng = np.random.default_rng(1)
    priors, news = ["old0", "old1", "old2"], ["new0", "new1", "new2"]
    centre = {o: 6.0 * rng.normal(size=(len(actions), 3)) for o in priors}
    centre.update({n: centre[o] + 0.3 for n, o in zip(news, priors)})  # each like one old

    def observe(objects, n):
        objs = np.repeat(objects, n)
        return {
            a: Observations.from_arrays(
                a,
                objs,
                force=np.array([centre[o][i, :1] for o in objs]) + rng.normal(size=(len(objs), 1)),
                thermal=np.array([centre[o][i, 1:] for o in objs])
                + rng.normal(size=(len(objs), 2)),
            )
            for i, a in enumerate(actions)
        }

    prior = PriorKnowledge.build(observe(priors, 4))
    pool, test = observe(news, 4), observe(news, 3)
    methods = {
        "APTKT": LearnerConfig(budget=2),
        "APTKT+aux": LearnerConfig(budget=2, auxiliary=True),
        "baseline": LearnerConfig(budget=2, transfer="none"),
    }
    rows = []
    for t in range(2):
        for name, cfg in methods.items():
            learner = APTKT(replace(cfg, seed=t), prior)
            run = learner.run(PoolEnvironment(pool, seed=t), list(actions), news, test)
            rows += [{"method": name, "run": t, **r} for r in step_rows(run, learner, news)]
    return rows, methods, tuple(news)


@pytest.mark.parametrize(("actions", "panels"), [(("press",), 1), (("press", "slide"), 2)])
def test_one_action_gets_one_panel(tmp_path, monkeypatch, actions, panels):
    rows, methods, news = _rows(actions)
    figures = {}

    def keep(fig, stem, *args, **kw):
        figures[stem.name] = fig
        return []

    monkeypatch.setattr(demo, "save_figure", keep)
    demo.report_results(
        tmp_path,
        rows,
        methods,
        news,
        budget=2,
        title="t",
        head={},
        size="table",
        files={},
        t_start=0.0,
        say=lambda line: None,
    )
    axes = [ax for ax in figures["learning_curves"].axes if ax.get_lines()]
    assert len(axes) == panels
    for ax in axes:
        _distinct_and_nested(_method_lines(ax, METHODS))
