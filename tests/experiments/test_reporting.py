"""What the plots and reports say: chance level and what the bands are, verdicts only where the
runs support one, and phrases that read as sentences."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.experiments.aggregate import Estimate, mean_band
from aptkt.experiments.figures.base import Headline
from aptkt.experiments.plots import BAND_LABEL, figure, learning_curves
from aptkt.experiments.report import (
    MIN_UNITS,
    TOO_FEW,
    gain_verdict,
    listed,
    no_harm_verdict,
    render_report,
    span,
)


def test_learning_curves_show_chance_and_95_percent_bands():
    rng = np.random.default_rng(0)
    runs = rng.uniform(0.3, 0.9, size=(5, 6))
    fig, ax = figure(1, 1)
    learning_curves(ax, {"APTKT": runs}, np.arange(6), chance=0.2)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert BAND_LABEL in labels and "95 %" in BAND_LABEL
    assert any(label.startswith("chance") for label in labels)
    chance = [ln for ln in ax.get_lines() if np.allclose(ln.get_ydata(), 0.2)]
    assert chance, "no line at chance level"
    (band,) = ax.collections
    ys = band.get_paths()[0].vertices[:, 1]
    _, low, high = mean_band(runs)
    assert ys.min() == pytest.approx(low.min()) and ys.max() == pytest.approx(high.max())
    with pytest.raises(TypeError):
        learning_curves(ax, {"APTKT": runs}, np.arange(6))  # chance level is not optional


def est(mean, low, high, n, unit="groups"):
    return Estimate(mean, low, high, n, unit)


def test_verdicts_need_enough_runs():
    # The quick size's 2 groups: an interval of ±12.7 standard errors supports nothing.
    few = est(-0.04, -0.696, 0.622, 2)
    assert gain_verdict(few, 0.10).startswith(TOO_FEW)
    assert no_harm_verdict(few).startswith(TOO_FEW)
    # Enough groups, but the interval holds both no gain and the paper's gain: still undecided.
    wide = est(0.03, -0.05, 0.12, 10)
    assert gain_verdict(wide, 0.10).startswith(TOO_FEW)
    # Enough groups and a decisive interval: a verdict.
    assert gain_verdict(est(0.11, 0.06, 0.16, 10), 0.10).startswith("agrees")
    assert gain_verdict(est(0.01, -0.01, 0.03, 10), 0.10).startswith("differs")
    assert no_harm_verdict(est(0.0, -0.01, 0.01, MIN_UNITS)).startswith("agrees")


def test_a_headline_on_too_few_runs_is_not_judged():
    h = Headline("fig9", "claim", "yes", "ours", "differs: it does not", [est(0.1, -0.5, 0.7, 2)])
    assert h.undecided and not h.agrees and h.verdict.startswith(TOO_FEW)
    ok = Headline("fig7", "claim", "yes", "ours", "agrees", [est(0.1, 0.05, 0.15, 10)])
    assert ok.agrees and not ok.undecided
    info = {
        "command": "aptkt reproduce",
        "software_version": "0",
        "date": "today",
        "seconds": 1.0,
        "executor": "local",
        "data": "d.h5",
        "fingerprint": "f",
        "seed": 0,
        "scale": "quick",
        "settings": {},
    }

    class S:
        figure, title, headlines, body, files = "fig9", "t", [h, ok], "", []

    text = render_report([S()], info)
    differs = text.split("## Where this run differs from the paper")[1].split("## fig9")[0]
    assert "Not judged" in differs and "- **fig9**" not in differs
    # A difference carries what the run measured about it, when the figure measured something.
    why = Headline("fig8", "claim", "yes", "ours", "differs: no", why="the baseline is at 0.9")
    plain = Headline("fig11", "other", "yes", "ours", "differs: no")

    class T:
        figure, title, headlines, body, files = "fig8", "t", [why, plain], "", []

    differs = render_report([T()], info).split("## Where this run differs")[1].split("## fig8")[0]
    lines = [line for line in differs.splitlines() if line.startswith("- **")]
    assert lines[0].endswith("*Why, measured in this run:* the baseline is at 0.9")
    assert "Why" not in lines[1]
    assert "Per-action average" in text and "what the paper's figures show" in text


def test_phrases_read_as_sentences():
    assert span([100.0, 100.0]) == "100 %"
    assert span([40.0, 75.2]) == "40–75 %"
    assert listed([]) == "" and listed(["S1", "S4"]) == " (S1, S4)"


def test_quick_demo_refuses_to_overwrite_a_full_result(tmp_path, capsys):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "summary.json").write_text(json.dumps({"size": "full"}))
    (out / "results.csv").write_text("precious")
    assert main(["demo", "--quick", "-o", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("aptkt demo: error:") and "full-size demo result" in err
    assert (out / "results.csv").read_text() == "precious"
    assert not (out / "data.h5").exists()
    # ... and a full run refuses a quick result's directory the same way.
    (out / "summary.json").write_text(json.dumps({"size": "quick"}))
    assert main(["demo", "-o", str(out), "--no-progress", "--runs", "1"]) == 1
    assert "quick-size demo result" in capsys.readouterr().err
