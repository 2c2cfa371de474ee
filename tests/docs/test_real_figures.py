"""The README's real-data figures are a benchmark run's own.

The BioTac set has no licence, so neither it nor anything derived from it is committed, its
benchmark results included: the figures cannot be checked against a file in the repository as
the simulated world's are (tests/docs/test_figures.py). Point ``APTKT_BIOTAC_BENCHMARK`` at the
output directory of the README's own command (``aptkt benchmark biotac.csv -o DIR -j 2``) and
this checks the README's table and its step-20 gains against that run's ``summary.json``; without
it the check is skipped, saying why. Re-measure, then run it, whenever the learner changes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from aptkt.experiments.aggregate import Estimate
from aptkt.experiments.report import ci

ROOT = Path(__file__).resolve().parents[2]
BENCHMARK = os.environ.get("APTKT_BIOTAC_BENCHMARK")
#: The README's names for the benchmark's prior choices.
CHOICES = {
    "random": "random priors",
    "nearest": "the most similar priors",
    "farthest": "the least similar priors",
}

needs_the_run = pytest.mark.skipif(
    BENCHMARK is None,
    reason="the BioTac benchmark's results may not be committed: set APTKT_BIOTAC_BENCHMARK to "
    "an 'aptkt benchmark biotac.csv' output directory to check the README against it",
)


def readme_rows(summary: dict) -> list[str]:
    """The README's table rows at one observation per new material, rendered from a run."""
    rows = []
    for choice, label in CHOICES.items():
        result = summary["results"]["3"][choice]
        gain = Estimate(**result["gain"]["APTKT"][0])
        baseline, aptkt = result["mean"]["baseline"][0], result["mean"]["APTKT"][0]
        rows.append(f"| {label} | {baseline:.3f} | {aptkt:.3f} | {ci(gain, cell=True)} |")
    return rows


def step_20_gains(summary: dict) -> str:
    gains = [summary["results"]["3"][c]["gain"]["APTKT"][20]["mean"] for c in CHOICES]
    return (
        f"at step 20 by {100 * gains[0]:+.1f}, {100 * gains[1]:+.1f} and {100 * gains[2]:+.1f} pp"
    )


@needs_the_run
def test_the_readme_quotes_the_biotac_run():
    summary = json.loads((Path(str(BENCHMARK)) / "summary.json").read_text())
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for row in readme_rows(summary):
        assert row in readme, f"README.md lacks the run's row:\n{row}"
    assert step_20_gains(summary) in " ".join(readme.split())


def test_the_rows_are_rendered_as_the_readme_writes_them():
    """The renderer itself, on a made-up run (so that the check above cannot pass vacuously)."""
    estimate = {"mean": 0.111, "low": 0.088, "high": 0.134, "n": 60, "unit": "groups"}
    later = {"mean": 0.019, "low": 0.005, "high": 0.033, "n": 60, "unit": "groups"}
    result = {
        "mean": {"baseline": [0.7657], "APTKT": [0.8771]},
        "gain": {"APTKT": [estimate] + [later] * 20},
    }
    summary = {"results": {"3": {c: result for c in CHOICES}}}
    assert readme_rows(summary)[0] == "| random priors | 0.766 | 0.877 | +11.1 pp [+8.8, +13.4] |"
    assert step_20_gains(summary) == "at step 20 by +1.9, +1.9 and +1.9 pp"
