"""What ``aptkt recognise`` writes: predictions.csv (one row per touch), summary.json, a
confusion plot (true object × predicted object, with a column for "new"), and the short summary
it prints."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from aptkt.errors import ConfigError
from aptkt.files import write_json_atomically
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
        **_outcomes(result),
    }


def _outcomes(result: Recognition) -> dict[str, Any]:
    """What became of the touches, as shares that add up to one: of the library's objects,
    accepted and right, flagged as new, or accepted as another object; of other objects,
    flagged as new or accepted as a library object. (The top guess alone, 'recognised', counts
    a touch that was flagged as new as right.)"""
    mine = result.in_library()
    known = np.asarray(result.known, dtype=bool)
    right = np.asarray(result.predicted) == np.asarray(result.object)
    out: dict[str, Any] = {"library_objects": None, "other_objects": None}
    if mine.any():
        out["library_objects"] = {
            "touches": int(mine.sum()),
            "accepted_and_right": float(np.mean(known[mine] & right[mine])),
            "flagged_new": float(np.mean(~known[mine])),
            "accepted_as_another_object": float(np.mean(known[mine] & ~right[mine])),
        }
    if (~mine).any():
        out["other_objects"] = {
            "touches": int((~mine).sum()),
            "flagged_new": float(np.mean(~known[~mine])),
            "accepted_as_a_library_object": float(np.mean(known[~mine])),
        }
    return out


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
    mine, other = s["library_objects"], s["other_objects"]
    if mine is not None:
        lines.append(
            f"{mine['touches']} touch(es) of objects in the library: "
            f"{100 * mine['accepted_and_right']:.1f} % accepted and right, "
            f"{100 * mine['flagged_new']:.1f} % flagged as new, "
            f"{100 * mine['accepted_as_another_object']:.1f} % accepted as another object "
            f"(top guess right: {100 * s['accuracy_on_library_objects']:.1f} %)"
        )
    if other is not None:
        lines.append(
            f"{other['touches']} touch(es) of objects not in the library: "
            f"{100 * other['flagged_new']:.1f} % flagged as new, "
            f"{100 * other['accepted_as_a_library_object']:.1f} % accepted as a library object"
            + (
                f"; novelty AUROC {s['novelty_auroc']:.3f}"
                if s["novelty_auroc"] is not None
                else ""
            )
        )
    return lines


#: A confusion plot shows at most this many touched objects (and the objects they were taken
#: for): a library of thousands would need a figure of metres.
MAX_CONFUSION_ROWS = 30


def plot_confusion(result: Recognition) -> Any:
    """Rows: the touches' true objects; columns: the library's objects and "new" (a touch not
    judged known); cells: the share of each row's touches. With more than
    :data:`MAX_CONFUSION_ROWS` touched objects, the rows are the ones recognised worst, and the
    columns the objects they were taken for."""
    truths = list(dict.fromkeys(result.object))
    index = {t: k for k, t in enumerate(truths)}
    said = [p if k else NEW for p, k in zip(result.predicted, result.known)]
    right = np.zeros(len(truths))
    touches = np.zeros(len(truths))
    for t, p in zip(result.object, said):
        touches[index[t]] += 1
        right[index[t]] += p == t
    title = "recognition: each touch's object, or new"
    if len(truths) > MAX_CONFUSION_ROWS:
        worst = np.argsort(right / touches, kind="stable")[:MAX_CONFUSION_ROWS]
        title += f" ({MAX_CONFUSION_ROWS} of {len(truths)} touched objects, the worst recognised)"
        truths = [truths[k] for k in sorted(worst)]
        index = {t: k for k, t in enumerate(truths)}
        taken = {p for t, p in zip(result.object, said) if t in index}
        columns = [o for o in result.library if o in taken] + [NEW]
    else:
        columns = [*result.library, NEW]
    where = {c: k for k, c in enumerate(columns)}
    counts = np.zeros((len(truths), len(columns)))
    for t, p in zip(result.object, said):
        if t in index:
            counts[index[t], where[p]] += 1
    shares = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
    from aptkt.experiments.plots import figure, label_shares

    # At most about 2,400 pixels wide (the figures are saved at 150 dpi).
    fig, ax = figure(1, 1, figsize=(min(0.45 * len(columns) + 3, 16.0), 0.4 * len(truths) + 2.2))
    image = ax.imshow(shares, cmap="Blues", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(columns)), columns, rotation=90)
    ax.set_yticks(range(len(truths)), truths)
    ax.set_xlabel("recognised as")
    ax.set_ylabel("touched object")
    label_shares(ax, shares, shown=counts > 0)
    fig.colorbar(image, ax=ax, label="share of the object's touches")
    ax.set_title(title)
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
    write_json_atomically(output / "summary.json", {**head, **summary(result)}, ConfigError)
    written.append(output / "summary.json")
    written += save_figure(plot_confusion(result), output / "confusion")
    for line in summary_lines(result):
        say(line)
    return written
