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


LIBRARY_SCALE = ROOT / "benches" / "results" / "library-scale.json"


def _figure(x: float) -> str:
    """Two significant figures below 10 (one decimal from 1), whole numbers above."""
    return f"{x:.2f}" if x < 1 else f"{x:.1f}" if x < 10 else f"{x:.0f}"


def library_scale_row(row: dict) -> str:
    """docs/results.md's row of the library benchmark at one size."""
    label = f"{row['objects']:,}" + (", the exact model" if row["model"] == "exact" else "")
    gb = row["peak MB"] / 1000
    cells = [
        f"{_figure(row['build CPU-s'])} CPU-s",
        f"{_figure(row['learn CPU-s'])} CPU-s",
        f"{row['update max ms']:.0f} ms",
        f"{_figure(row['recognise ms/touch'])} ms",
        f"{_figure(row['merge CPU-s'])} CPU-s",
        f"{gb:.2f} GB" if gb < 1 else f"{gb:.1f} GB",
    ]
    return f"| {label} | {' | '.join(cells)} |"


def test_the_library_of_thousands_is_the_benchmarks_file():
    """The table of what a library costs as it grows is benches/results/library-scale.json's,
    with the command that wrote it."""
    bench, page = json.loads(LIBRARY_SCALE.read_text()), PAGE.read_text()
    rows = {(r["objects"], r["model"]): r for r in bench["rows"]}
    shown = [(100, "exact"), (100, "local"), (1000, "local"), (10000, "local")]
    for key in shown:
        assert library_scale_row(rows[key]) in page, library_scale_row(rows[key])
    assert f"python benches/{' '.join(bench['command'])}" in page


def test_the_library_rows_render_as_the_page_writes_them():
    row = {
        "objects": 1000,
        "model": "local",
        "build CPU-s": 6.46,
        "learn CPU-s": 2.02,
        "update max ms": 64.9,
        "recognise ms/touch": 0.368,
        "merge CPU-s": 66.63,
        "peak MB": 8757,
    }
    assert library_scale_row(row) == (
        "| 1,000 | 6.5 CPU-s | 2.0 CPU-s | 65 ms | 0.37 ms | 67 CPU-s | 8.8 GB |"
    )


SELECTION = ROOT / "docs" / "results" / "simulated-selection.json"


def test_the_simulated_selection_study_is_its_run():
    """docs/method.md's figures of the learners' own choice against random picks on the
    simulated world are docs/results/simulated-selection.json's (that run's summary.json)."""
    from aptkt.experiments.aggregate import Estimate
    from aptkt.experiments.report import ci, pp

    summary = json.loads(SELECTION.read_text())
    arms = {a["learner"]: a for a in summary["active_against_random"]}

    def touches(a: dict) -> str:
        lo, hi = a["touches_interval"]
        return f"{a['touches']:.1f} touches [{lo:.1f}, {hi:.1f}]"

    def gain(a: dict) -> str:
        return ci(Estimate(**a["mean_gain"]), cell=True)

    aptkt, baseline = arms["APTKT"], arms["baseline"]
    mean = summary["results"]["3"]["random"]["mean"]["APTKT"]
    figures = [
        f"APTKT {gain(aptkt)} over random picks",
        f"(lowest {pp(aptkt['lowest'])}, step {aptkt['lowest_step']})",
        f"never falling by more than {100 * aptkt['largest_fall']:.1f} pp",
        f"after {touches(aptkt)}",
        f"the baseline {gain(baseline)} (lowest {pp(baseline['lowest'])}, {touches(baseline)})",
        f"rises {100 * (mean[20] - mean[0]):.1f} pp in 20 touches",
        summary["date"],
    ]
    page = " ".join((ROOT / "docs" / "method.md").read_text().replace("−", "-").split())
    missing = [f for f in figures if f not in page]
    assert not missing, missing


NOISE_PROFILE = ROOT / "docs" / "results" / "simulated-noise-profile.json"


def test_the_simulated_worlds_noise_by_modality_is_its_profile():
    """docs/simulation.md's figures of the reproduction's data set by modality are
    docs/results/simulated-noise-profile.json's."""
    from aptkt.experiments.report import span

    profile = json.loads(NOISE_PROFILE.read_text())["profile"]

    def figures(figure: str, *modalities: str, actions: tuple[str, ...] = ()) -> str:
        values = [
            p[figure]
            for p in profile
            if p["modality"] in modalities and (not actions or p["action"] in actions)
        ]
        return span(values, "{:.1f}", "")

    drifting_little = tuple(
        p["action"] for p in profile if p["modality"] == "texture" and p["drift"] < 1.5
    )
    named = ", ".join(drifting_little[:-1]) + f" and {drifting_little[-1]}"
    quoted = [
        f"the force separates the objects by {figures('separation', 'force')}",
        f"the thermal curve by {figures('separation', 'thermal')}",
        f"the texture by {figures('separation', 'texture')}",
        f"the texture of {named} still drifts little "
        f"({figures('drift', 'texture', actions=drifting_little)}, against",
        f"less unequal between objects ({figures('heterogeneity', 'thermal')}) than the force's "
        f"and the texture's ({figures('heterogeneity', 'force', 'texture')})",
        "docs/results/simulated-noise-profile.json",
    ]
    page = " ".join((ROOT / "docs" / "simulation.md").read_text().split())
    missing = [q for q in quoted if q not in page]
    assert not missing, missing
