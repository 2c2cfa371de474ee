"""Figures the docs quote from a measured run are the run's own: its summary is committed beside
the docs (docs/results/), and each table the page shows is rendered again from it here, so a
re-measured run and the page that quotes it cannot drift apart."""

from __future__ import annotations

import json
from pathlib import Path

from aptkt.experiments.beside_real import COLUMNS
from aptkt.experiments.report import markdown_table

ROOT = Path(__file__).resolve().parents[2]
SIMULATED = ROOT / "docs" / "results" / "simulated-world.json"
PAGE = ROOT / "docs" / "results.md"


def _summary() -> dict:
    return json.loads(SIMULATED.read_text())


def test_the_simulated_worlds_headlines_are_its_runs():
    summary, page = _summary(), PAGE.read_text()
    rows = [
        [h["figure"], h["claim"], h["paper"], h["ours"], h["verdict"]] for h in summary["headlines"]
    ]
    assert len(rows) >= 8
    assert markdown_table(["figure", "claim", "paper", "this run", "verdict"], rows) in page
    # Where it came from: the command, the version and the day.
    assert summary["command"] in page
    assert summary["date"][:10] in page


def test_the_simulated_world_beside_real_data_is_the_runs_comparison():
    beside, page = _summary()["beside_real"], PAGE.read_text()
    assert beside is not None and beside["columns"] == list(COLUMNS)
    assert markdown_table(beside["columns"], beside["rows"]) in page


def test_the_simulated_worlds_time_is_its_runs():
    assert f"Time: {_summary()['seconds']:,.0f} s wall" in PAGE.read_text()
