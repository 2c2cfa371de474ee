"""`aptkt demo --quick` end to end: simulated data, prior knowledge, learning, plots, results."""

import csv
import json

import numpy as np
import pytest

from aptkt.cli import main


@pytest.mark.slow
def test_quick_demo_writes_every_output(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "-o", str(out), "--no-progress", "-j", "2"]) == 0
    printed = capsys.readouterr().out
    for step in ("[1/5]", "[2/5]", "[3/5]", "[4/5]", "[5/5]"):
        assert step in printed
    for name in (
        "data.h5",
        "prior.npz",
        "results.csv",
        "summary.json",
        "learning_curves.png",
        "learning_curves.svg",
        "confusion.png",
        "confusion.svg",
        "confusion.csv",
    ):
        assert (out / name).stat().st_size > 0, name
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["final_mean_accuracy"]) == {"APTKT", "APTKT+aux", "baseline"}
    rows = list(csv.DictReader((out / "results.csv").open()))
    methods = {r["method"] for r in rows}
    assert methods == {"APTKT", "APTKT+aux", "baseline"}
    budget = summary["settings"]["budget"]
    assert {int(r["step"]) for r in rows} == set(range(budget + 1))
    # The table printed is the one computed from the rows.
    for line in summary["table"][2:]:
        assert line in printed
    # Fused accuracy beside the per-action average, chance level, and what ± means.
    assert set(summary["final_fused_accuracy"]) == {"APTKT", "APTKT+aux", "baseline"}
    assert [line[10:26].strip() for line in summary["table"]].count("fused") == 3
    assert "chance level 0.333" in printed and "95 % interval" in printed
    svg = (out / "learning_curves.svg").read_text()
    assert "chance" in svg and "95 % interval" in svg
    # The final models' confusion between the new objects, for the baseline and APTKT: every
    # test observation of every action counted once per run.
    confusion = summary["final_confusion"]
    n_test = summary["settings"]["test_reps"] * len(summary["settings"]["actions"])
    for method in ("baseline", "APTKT"):
        counts = np.array(confusion[method])
        assert counts.shape == (3, 3)
        assert (counts.sum(axis=1) == n_test * summary["settings"]["trials"]).all()
    csv_rows = list(csv.DictReader((out / "confusion.csv").open()))
    assert {r["method"] for r in csv_rows} == {"baseline", "APTKT"}
    assert "true object" in (out / "confusion.svg").read_text()
    # Per action and new object, what APTKT learned from (or why not), printed and in report.md,
    # with the relatedness heat-map of each method that transfers.
    assert "transfer at the end of the runs (APTKT;" in printed
    lines = summary["transfer"]["APTKT"]
    new_objects = ("smooth_sponge", "hard_box", "biscuit_box")
    actions = summary["settings"]["actions"]
    assert len(lines) == len(actions) * len(new_objects)
    for k, line in enumerate(lines):
        assert "        " + line in printed.splitlines()
        assert line.split()[0 if k % 3 else 1].rstrip(":") == new_objects[k % 3]
        assert " <- " in line or "no transfer" in line
    report = (out / "report.md").read_text()
    assert all(line in report for line in summary["transfer"]["APTKT+aux"])
    for name in ("transfer_APTKT.png", "transfer_APTKT_aux.png", "learning_curves.png"):
        assert f"({name})" in report and (out / name).stat().st_size > 0
    # A second run reuses the simulated data.
    assert main(["demo", "--quick", "-o", str(out), "--no-progress", "-j", "2"]) == 0
    assert "(0 simulated now" in capsys.readouterr().out
