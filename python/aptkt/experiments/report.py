"""The Markdown report: our numbers beside the paper's headline figures, with verdicts.

Only the paper's reference figures (:data:`PAPER`) are constants here; every number of ours
that the report prints is computed from the run's results by the figure modules and passed in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from aptkt.experiments.aggregate import Estimate

__all__ = [
    "PAPER",
    "pp",
    "ci",
    "gain_verdict",
    "no_harm_verdict",
    "render_report",
    "markdown_table",
    "MIN_UNITS",
    "TOO_FEW",
    "too_few",
    "listed",
    "span",
]

#: Fewest independent units (groups, or runs) behind an estimate for a verdict: with two, the
#: 95 % t interval is ±12.7 standard errors and supports no conclusion either way.
MIN_UNITS = 3
#: How every verdict the runs cannot support begins.
TOO_FEW = "too few runs to judge"

#: The paper's headline figures (Feng, Kaboli & Cheng, Sensors 18(2):634, 2018, §5.3–5.6;
#: docs/design.md §6). Gains are fractions.
PAPER: Mapping[str, Any] = {
    "fig6_beats": ("P1", "P2", "C1", "S4"),
    "fig6_matches": ("S1", "S2", "S3"),
    "fig7_gain": 0.10,
    "fig8_P2_gain": 0.25,
    "fig8_little": ("S1", "S4"),
    "fig8_larger": ("P1", "P2", "C1"),
    "fig9_aux_gain_10_priors": 0.20,
    # Fig. 10: the priors (by number) the paper found dissimilar to the new objects.
    "fig10_dissimilar": {
        "P1": (1, 5, 7),
        "P2": (1, 4, 7),
        "C1": (4, 7, 10),
        "S1": (1, 6, 9),
        "S2": (1, 7, 10),
        "S3": (1, 3, 9),
        "S4": (1, 3, 8),
        "all": (1, 5, 10),
    },
}


def pp(x: float, sign: bool = True) -> str:
    """A fraction as percentage points, e.g. ``+10.3 pp``."""
    if x is None or not math.isfinite(x):
        return "n/a"
    return f"{100 * x:+.1f} pp" if sign else f"{100 * x:.1f} %"


def ci(e: Estimate, *, cell: bool = False) -> str:
    """``+10.3 pp [+4.1, +16.5] (95 % CI, 10 groups)``; in a table's cell (``cell``), whose
    heading says what the interval is, ``+10.3 pp [+4.1, +16.5]``."""
    if not math.isfinite(e.mean):
        return "n/a (no runs)"
    if not math.isfinite(e.low):
        return f"{pp(e.mean)} (1 {e.unit.rstrip('s')}: no interval)"
    interval = f"{pp(e.mean)} [{100 * e.low:+.1f}, {100 * e.high:+.1f}]"
    return interval if cell else f"{interval} (95 % CI, {e.n} {e.unit})"


def too_few(*estimates: Estimate) -> bool:
    """Whether any estimate rests on fewer than :data:`MIN_UNITS` units or has no interval."""
    return any(e.n < MIN_UNITS or not math.isfinite(e.low) for e in estimates)


def listed(items: Sequence[str]) -> str:
    """`` (a, b)`` after a count, or nothing for an empty list."""
    return f" ({', '.join(items)})" if items else ""


def span(values: Sequence[float], fmt: str = "{:.0f}", unit: str = " %") -> str:
    """``40–75 %`` for a range of values, ``100 %`` when they are all the same."""
    lo, hi = fmt.format(min(values)), fmt.format(max(values))
    return f"{lo}{unit}" if lo == hi else f"{lo}–{hi}{unit}"


def gain_verdict(e: Estimate, paper: float) -> str:
    """Compare a gain over the baseline with the paper's (positive) gain."""
    if too_few(e):
        return f"{TOO_FEW} ({e.n} {e.unit})"
    if e.low < 0 < e.high and e.low < paper < e.high:
        return f"{TOO_FEW}: the 95 % interval holds both no gain and the paper's {pp(paper)}"
    if e.significant_negative:
        return f"differs: APTKT is significantly worse than the baseline (paper: {pp(paper)})"
    if not e.significant_positive:
        return f"differs: no significant gain (paper: {pp(paper)})"
    ratio = e.mean / paper
    if 0.5 <= ratio <= 2.0:
        return "agrees: a significant gain of the paper's size (within a factor of 2)"
    if ratio < 0.5:
        return f"differs in size: a significant gain, but less than half the paper's {pp(paper)}"
    return f"differs in size: a significant gain, more than twice the paper's {pp(paper)}"


def no_harm_verdict(e: Estimate) -> str:
    """The paper's negative-transfer claim: APTKT is not worse than the baseline."""
    if too_few(e):
        return f"{TOO_FEW} ({e.n} {e.unit})"
    if e.significant_negative:
        return "differs: negative transfer — APTKT significantly below the baseline"
    if e.significant_positive:
        return "agrees (no negative transfer); APTKT is even significantly better, where the paper saw ≈ equal"
    return "agrees: APTKT ≈ baseline (difference not significant)"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    def cell(v: Any) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)


def render_report(sections: Sequence[Any], run_info: Mapping[str, Any]) -> str:
    """The whole report: headline table, differences, figure sections, configuration."""
    out = [
        "# Reproduction of the paper's experiments on the simulated world",
        "",
        f"`{run_info['command']}` — aptkt {run_info['software_version']}, {run_info['date']}, "
        f"{run_info['seconds']:.0f} s on {run_info['executor']}.",
        "",
        f"Data: `{run_info['data']}` (fingerprint `{run_info['fingerprint']}`); root seed {run_info['seed']}; "
        f"size: **{run_info['scale']}**. Everything needed to repeat this run exactly is in `config.json`; "
        "every step of every run is in the figures' `results.csv`.",
        "",
        "The world is simulated: the objects are modelled after the paper's, not measured, so the aim is "
        "to see whether the paper's findings hold *in shape* here — not to match its numbers. Gains are "
        "APTKT minus baseline accuracy on the test set, in percentage points (pp), paired run by run.",
        "",
        "Accuracy is measured two ways. *Per-action average*: each action's model classifies that "
        "action's test observations and the accuracies are averaged over actions — this is what the "
        "paper's figures show, and what the headline numbers and verdicts use. *Fused*: the posteriors "
        "of all actions' models are combined for each test object (a product, as independent "
        "evidence) — reported beside it, where a run uses more than one action. Learning-curve bands "
        "are 95 % intervals of the mean over runs; the dashed line is chance level.",
        "",
        "## Headline figures: paper vs this run",
        "",
    ]
    heads = [h for s in sections for h in s.headlines]
    out.append(
        markdown_table(
            ["figure", "claim", "paper", "this run", "verdict"],
            [[h.figure, h.claim, h.paper, h.ours, h.verdict] for h in heads],
        )
    )
    undecided = [h for h in heads if h.undecided]
    differ = [h for h in heads if not h.agrees and not h.undecided]
    out += ["", "## Where this run differs from the paper", ""]
    if differ:
        out += [
            f"- **{h.figure}** — {h.claim}: paper {h.paper}; here {h.ours}. {h.verdict[0].upper()}{h.verdict[1:]}."
            + (f" *Why, measured in this run:* {h.why}" if h.why else "")
            for h in differ
        ]
    elif undecided:
        out.append("No headline claim that this run can judge differs from the paper.")
    else:
        out.append("Every headline claim above agrees in shape.")
    if undecided:
        out += [
            "",
            f"Not judged — {TOO_FEW} ({len(undecided)} of {len(heads)} claims; a verdict needs at "
            f"least {MIN_UNITS} independent groups or runs and an interval that excludes one of "
            "the outcomes): " + "; ".join(f"{h.figure} {h.claim}" for h in undecided) + ".",
        ]
    for s in sections:
        out += ["", f"## {s.figure}: {s.title}", "", s.body.strip(), ""]
        if s.files:
            out.append("Files: " + ", ".join(f"`{f}`" for f in s.files))
    out += [
        "",
        "## Configuration",
        "",
        markdown_table(["setting", "value"], [[k, v] for k, v in run_info["settings"].items()]),
        "",
    ]
    return "\n".join(out) + "\n"
