"""What ``aptkt recognise`` writes: predictions.csv (one row per touch), summary.json, a
confusion plot (true object × predicted object, with a column for "new"), and the short summary
it prints."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.learning.recognition import Recognition

__all__ = ["summary_lines", "write_recognition", "plot_confusion"]

NEW = "(new)"


def summary(result: Recognition) -> dict[str, Any]:
    cal = result.calibration
    accuracy = result.accuracy()
    auroc = result.novelty_auroc()
    mine = result.in_library()
    return {
        "touches": len(result),
        "library": result.library,
        "threshold": cal.threshold,
        "false_alarm_rate": cal.false_alarm_rate,
        "detection_rate_on_the_library": cal.detection_rate,
        "accuracy_on_library_objects": accuracy,
        "flagged_new_among_library_objects": float(np.mean(~result.known[mine]))
        if mine.any()
        else None,
        "flagged_new_among_other_objects": float(np.mean(~result.known[~mine]))
        if (~mine).any()
        else None,
        "novelty_auroc": auroc,
    }


def summary_lines(result: Recognition) -> list[str]:
    """The printed summary: how many touches, accuracy where the true object is in the
    library, novelty AUROC where other objects are present, and the threshold's rates."""
    s = summary(result)
    lines = [
        f"{s['touches']} touch(es) against a library of {len(result.library)} objects; "
        f"'known' at novelty <= {s['threshold']:.2f} (chosen on the library for a false-alarm "
        f"rate of {100 * s['false_alarm_rate']:.0f} %; it catches "
        f"{100 * s['detection_rate_on_the_library']:.0f} % of its own objects left out)"
    ]
    if s["accuracy_on_library_objects"] is not None:
        lines.append(
            f"objects in the library: {100 * s['accuracy_on_library_objects']:.1f} % recognised, "
            f"{100 * s['flagged_new_among_library_objects']:.1f} % flagged as new"
        )
    if s["flagged_new_among_other_objects"] is not None:
        lines.append(
            f"objects not in the library: {100 * s['flagged_new_among_other_objects']:.1f} % "
            "flagged as new"
            + (
                f"; novelty AUROC {s['novelty_auroc']:.3f}"
                if s["novelty_auroc"] is not None
                else ""
            )
        )
    return lines


def plot_confusion(result: Recognition) -> Any:
    """Rows: the touches' true objects; columns: the library's objects and "new" (a touch not
    judged known); cells: the share of each row's touches."""
    truths = list(dict.fromkeys(result.object))
    columns = [*result.library, NEW]
    counts = np.zeros((len(truths), len(columns)))
    for t, p, k in zip(result.object, result.predicted, result.known):
        counts[truths.index(t), columns.index(p if k else NEW)] += 1
    shares = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
    from aptkt.experiments.plots import figure, label_shares

    fig, ax = figure(1, 1, figsize=(0.45 * len(columns) + 3, 0.4 * len(truths) + 2.2))
    image = ax.imshow(shares, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(columns)), columns, rotation=90)
    ax.set_yticks(range(len(truths)), truths)
    ax.set_xlabel("recognised as")
    ax.set_ylabel("touched object")
    label_shares(ax, shares, shown=counts > 0)
    fig.colorbar(image, ax=ax, label="share of the object's touches")
    ax.set_title("recognition: each touch's object, or new")
    fig.tight_layout()
    return fig


def write_recognition(
    result: Recognition, output: Path, *, head: dict[str, Any], say: Callable[[str], None] = print
) -> list[Path]:
    """predictions.csv, summary.json and confusion.png/.svg in ``output``."""
    from aptkt.experiments.plots import save_figure
    from aptkt.experiments.tables import write_csv

    output.mkdir(parents=True, exist_ok=True)
    written = [write_csv(output / "predictions.csv", result.rows())]
    (output / "summary.json").write_text(json.dumps({**head, **summary(result)}, indent=1))
    written.append(output / "summary.json")
    written += save_figure(plot_confusion(result), output / "confusion")
    for line in summary_lines(result):
        say(line)
    return written
