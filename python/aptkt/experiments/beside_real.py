"""The reproduction's gains beside a real-data benchmark's (``aptkt benchmark``): how far the
simulated world's numbers predict what a real sensor gives."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from aptkt.errors import ConfigError
from aptkt.experiments.report import markdown_table, pp

__all__ = ["load_benchmark", "beside_real", "comparison"]

#: The comparison's columns, in the report's table and in summary.json.
COLUMNS = ("", "this run (simulated)", "real data", "simulated / real")


def load_benchmark(directory: str | Path) -> dict[str, Any]:
    """The summary of an ``aptkt benchmark`` output directory, checked. Its results are given
    per library size; the smallest library's are the ones compared (``library`` says its
    size): the benchmark's checks are made there, and Fig. 7's libraries are as small."""
    path = Path(directory) / "summary.json"
    try:
        summary = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"--real-data {directory}: no benchmark summary ({exc})") from None
    results = summary.get("results") if isinstance(summary, dict) else None
    if isinstance(results, dict) and "random" not in results:
        sizes = sorted(
            (int(size), entry)
            for size, entry in results.items()
            if str(size).isdigit() and isinstance(entry, dict) and "random" in entry
        )
        if sizes:
            summary = {**summary, "library": sizes[0][0], "results": sizes[0][1]}
            results = summary["results"]
    if not isinstance(results, dict) or "random" not in results:
        raise ConfigError(
            f"--real-data {directory}: {path} is not the summary of an aptkt benchmark with "
            "random priors"
        )
    return summary


def _gain(results: Mapping[str, Any], choice: str, step: int) -> float | None:
    try:
        return float(results[choice]["gain"]["APTKT"][step]["mean"])
    except (KeyError, IndexError, TypeError):
        return None


def _largest_fall(entry: Mapping[str, Any]) -> float:
    falls = []
    for method, curve in entry["mean"].items():
        if method != "1-NN" and len(curve) > 1:
            falls.append(max(a - b for a, b in zip(curve, curve[1:])))
    return max(falls, default=0.0)


def comparison(numbers: Mapping[str, Any], real: Mapping[str, Any]) -> list[list[str]]:
    """The rows (see :data:`COLUMNS`): Fig. 7's gains (related priors) beside the benchmark's
    random priors, and Fig. 11's question (dissimilar priors) beside its least similar ones."""
    results = real["results"]
    rows = []
    fig7 = numbers.get("fig7")
    if fig7:
        at = fig7["gain"]["at_step"]
        sim0 = float((at[0] if 0 in at else at["0"])["mean"])
        sim_all = float(fig7["gain"]["overall"]["mean"])
        real0 = _gain(results, "random", 0)
        curve = [g["mean"] for g in results["random"]["gain"]["APTKT"]]
        real_all = sum(curve) / len(curve)
        rows.append(
            [
                "APTKT − baseline at one observation per object",
                pp(sim0),
                pp(real0) if real0 is not None else "",
                f"{sim0 / real0:.1f}×" if real0 else "",
            ]
        )
        rows.append(
            [
                "APTKT − baseline over the curve",
                pp(sim_all),
                pp(real_all),
                f"{sim_all / real_all:.1f}×" if real_all else "",
            ]
        )
    if "farthest" in results:
        lowest = min(g["mean"] for g in results["farthest"]["gain"]["APTKT"])
        rows.append(["least similar priors: lowest gain at any step", "(Fig. 11)", pp(lowest), ""])
    fall = max(_largest_fall(entry) for entry in results.values())
    rows.append(
        ["largest fall of a mean curve in one step (real data)", "", f"{100 * fall:.1f} pp", ""]
    )
    return rows


def beside_real(real: Mapping[str, Any] | None, rows: list[list[str]]) -> list[str]:
    """The report's section: the rows of :func:`comparison` with where the real data came
    from."""
    lines = ["## The simulated world beside real data", ""]
    if real is None:
        return lines + [
            "No real-data benchmark was given. `aptkt benchmark TABLE -o DIR` on a real sensor's "
            "feature table (docs/real-data.md), then `aptkt reproduce ... --real-data DIR`, "
            "puts its gains here beside this run's.",
            "",
        ]
    results = real["results"]
    lines += [
        f"Real data: `{real.get('table', '?')}` ({real.get('objects', '?')} objects, "
        f"{results['random'].get('groups', '?')} groups"
        + (f", {real['library']} prior objects" if "library" in real else "")
        + f"; `{real.get('command', '')}`). The "
        "simulated Fig. 7 uses priors related to the new objects by design; the real benchmark's "
        "random priors are its closest counterpart.",
        "",
        markdown_table(list(COLUMNS), rows),
        "",
    ]
    return lines
