"""The lifelong benchmark's analysis (see :mod:`aptkt.experiments.lifelong`): per batch, APTKT
against the baseline at one observation per object and at the end of the budget, and the grown
library against a nearest-class-mean rule, paired by order with 95 % intervals; the checks;
the plot and report.md."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt.experiments.aggregate import Estimate, estimate, mean_band
from aptkt.experiments.benchmark_report import ROUNDING, Check, checks_table, curve_matrix
from aptkt.experiments.plots import figure
from aptkt.experiments.report import ci, markdown_table, pp

__all__ = ["tables", "checks", "summary", "plot", "report_markdown"]

#: batch -> method -> (orders × steps) accuracies; "library" and "NCM" have one column.
Tables = Mapping[int, Mapping[str, np.ndarray]]


def tables(rows: Sequence[Mapping[str, Any]]) -> dict[int, dict[str, np.ndarray]]:
    """Batch -> method -> (orders × steps) accuracies, orders in order; ``"size"`` holds the
    library's size after the batch was merged (orders × 1)."""
    out: dict[int, dict[str, dict[int, dict[int, float]]]] = {}
    sizes: dict[int, dict[int, float]] = {}
    for r in rows:
        b, o = int(r["batch"]), int(r["order"])
        out.setdefault(b, {}).setdefault(str(r["method"]), {}).setdefault(o, {})[int(r["step"])] = (
            float(r["accuracy"])
        )
        if r["method"] == "library":
            sizes.setdefault(b, {})[o] = float(r["library"])
    result: dict[int, dict[str, np.ndarray]] = {}
    for b in sorted(out):
        result[b] = {method: curve_matrix(per_order) for method, per_order in out[b].items()}
        if b in sizes:
            result[b]["size"] = np.array([[sizes[b][o]] for o in sorted(sizes[b])])
    return result


def _paired(a: np.ndarray, b: np.ndarray) -> Estimate:
    return estimate(a - b, units=list(range(len(a))), unit_name="order")


def _last(values: np.ndarray) -> int:
    return int(values.shape[1] - 1)


def checks(c: Tables) -> list[Check]:
    """The third batch's one-shot gain at least the first's (paired by order: the first batch
    learns from the starting library, the third from it and two learned batches); after the
    last batch, the library at least the nearest-class-mean rule."""
    out = []
    batches = sorted(c)
    if 1 in c and 3 in c:
        first = _paired(c[1]["APTKT"][:, 0], c[1]["baseline"][:, 0])
        third = _paired(c[3]["APTKT"][:, 0], c[3]["baseline"][:, 0])
        diff = _paired(
            c[3]["APTKT"][:, 0] - c[3]["baseline"][:, 0],
            c[1]["APTKT"][:, 0] - c[1]["baseline"][:, 0],
        )
        out.append(
            Check(
                "the third batch's one-shot gain over the baseline is at least the first's",
                f"{pp(third.mean)} against {pp(first.mean)} (difference {ci(diff)})",
                third.mean >= first.mean - ROUNDING,
            )
        )
    if batches:
        last = batches[-1]
        m = c[last]
        d = _paired(m["library"][:, 0], m["NCM"][:, 0])
        size = int(np.nanmean(m["size"])) if "size" in m else 0
        out.append(
            Check(
                f"after the last batch the library ({size} objects) is at least as accurate as "
                "the nearest class mean in its metric on the same observations",
                f"{np.nanmean(m['library']):.3f} against {np.nanmean(m['NCM']):.3f} ({ci(d)})",
                d.mean >= -ROUNDING,
            )
        )
    return out


def summary(c: Tables) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for b, m in c.items():
        last = _last(m["APTKT"])
        out[str(b)] = {
            "library_size": float(np.nanmean(m["size"])) if "size" in m else None,
            "mean": {k: np.nanmean(v, axis=0).tolist() for k, v in m.items() if k != "size"},
            "gain_one_shot": _paired(m["APTKT"][:, 0], m["baseline"][:, 0]).as_dict(),
            "gain_last_step": _paired(m["APTKT"][:, last], m["baseline"][:, last]).as_dict(),
            "library_vs_ncm": _paired(m["library"][:, 0], m["NCM"][:, 0]).as_dict(),
        }
    return out


def plot(c: Tables) -> Any:
    """Left: APTKT's gain over the baseline per batch, at one observation per object and at
    the end of the budget (95 % intervals over orders). Right: the grown library's accuracy on
    every object it holds, and the nearest class mean's."""
    batches = sorted(c)
    fig, axes = figure(1, 2, figsize=(10.0, 4.2), squeeze=False)
    left, right = axes[0]
    x = np.asarray(batches, dtype=float)
    for offset, (label, step_of, look) in enumerate(
        (
            ("one observation per object", lambda m: 0, {"color": "C2", "marker": "o", "ls": "-"}),
            ("end of the budget", _last, {"color": "C0", "marker": "s", "ls": "--"}),
        )
    ):
        est = [
            _paired(
                c[b]["APTKT"][:, step_of(c[b]["APTKT"])],
                c[b]["baseline"][:, step_of(c[b]["APTKT"])],
            )
            for b in batches
        ]
        mean = np.array([100 * e.mean for e in est])
        err = np.array([[100 * (e.mean - e.low), 100 * (e.high - e.mean)] for e in est]).T
        left.errorbar(
            x + 0.06 * (offset - 0.5), mean, yerr=np.nan_to_num(err), capsize=3, label=label, **look
        )
    left.axhline(0, color="0.3", lw=1)
    left.set_ylabel("APTKT − baseline (pp, 95 % intervals)")
    left.set_title("learning each batch")
    for method, look in (
        ("library", {"color": "C3", "marker": "o", "ls": "-"}),
        ("NCM", {"color": "0.4", "marker": "D", "ls": ":"}),
    ):
        bands = [mean_band(c[b][method]) for b in batches]
        mean = np.array([bd[0][0] for bd in bands])
        low = np.array([bd[1][0] for bd in bands])
        high = np.array([bd[2][0] for bd in bands])
        right.errorbar(
            x,
            mean,
            yerr=np.nan_to_num([mean - low, high - mean]),
            capsize=3,
            label="the library's model" if method == "library" else "nearest class mean",
            **look,
        )
    lowest = min(float(np.nanmin(c[b][m])) for b in batches for m in ("library", "NCM"))
    right.set_ylim(max(0.0, lowest - 0.1), 1.0)
    right.set_ylabel("accuracy on every object it holds")
    right.set_title("the grown library")
    for ax in (left, right):
        ax.set_xticks(batches)
        labels = []
        for b in batches:
            size = int(np.nanmean(c[b]["size"])) if "size" in c[b] else 0
            labels.append(f"{b}\n({size} objects)" if size else str(b))
        ax.set_xticklabels(labels)
        ax.set_xlabel("batch (library size after merging it)")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def report_markdown(c: Tables, head: Mapping[str, Any], found: Sequence[Check]) -> str:
    batches = sorted(c)
    lines = [
        f"# Lifelong benchmark: {head['table']}",
        "",
        f"Command: `{head['command']}`  ",
        f"aptkt {head['software_version']}; {head['seconds']:.0f} s on {head['jobs']} "
        f"process(es); {head['date']}.",
        "",
        f"{head['objects']} objects, action(s) {', '.join(head['actions'])}, {head['orders']} "
        f"random orders. In each, the first {head['batch']} objects are the starting library "
        "(the first half of their trials); then each batch of "
        f"{head['batch']} is learned — APTKT with the whole library, the baseline with nothing, "
        f"one observation per object then {head['budget']} actively chosen — and the "
        "observations APTKT made are merged into the library, which is refitted. Accuracy on "
        "the held-out second half of the trials; gains paired by order, 95 % Student-t "
        "intervals over orders.",
        "",
        "## Checks",
        "",
        checks_table(found),
        "",
        "## Per batch",
        "",
    ]
    rows = []
    for b in batches:
        m = c[b]
        last = _last(m["APTKT"])
        size = int(np.nanmean(m["size"])) if "size" in m else ""
        mean = {k: np.nanmean(v, axis=0) for k, v in m.items()}
        rows.append(
            [
                str(b),
                str(int(size) - head["batch"]) if size != "" else "",
                f"{mean['baseline'][0]:.3f} → {mean['baseline'][last]:.3f}",
                f"{mean['APTKT'][0]:.3f} → {mean['APTKT'][last]:.3f}",
                ci(_paired(m["APTKT"][:, 0], m["baseline"][:, 0])),
                ci(_paired(m["APTKT"][:, last], m["baseline"][:, last])),
                f"{size}",
                f"{mean['library'][0]:.3f} / {mean['NCM'][0]:.3f}",
                ci(_paired(m["library"][:, 0], m["NCM"][:, 0])),
            ]
        )
    last = _last(c[batches[0]]["APTKT"]) if batches else 0
    lines += [
        markdown_table(
            [
                "batch",
                "priors",
                f"baseline step 0 → {last}",
                f"APTKT step 0 → {last}",
                "APTKT − baseline, step 0",
                f"APTKT − baseline, step {last}",
                "library size",
                "library / nearest class mean",
                "library − nearest class mean",
            ],
            rows,
        ),
        "",
        "Plot: `lifelong.png` / `.svg`. Every order's numbers: `results.csv`; the summary: "
        "`summary.json`.",
        "",
    ]
    return "\n".join(lines)
