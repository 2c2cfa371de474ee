"""The lifelong benchmark's analysis (see :mod:`aptkt.experiments.lifelong`): per batch, APTKT
against the baseline at one observation per object and at the end of the budget, and the grown
library against a nearest-class-mean rule, paired by order with 95 % intervals; the checks;
the plot and report.md."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aptkt.experiments.aggregate import Estimate, estimate, mean_band
from aptkt.experiments.benchmark_report import (
    REFERENCE,
    ROUNDING,
    Check,
    checks_table,
    curve_matrix,
)
from aptkt.experiments.plots import figure
from aptkt.experiments.report import ci, markdown_table, pp

__all__ = ["tables", "checks", "summary", "plot", "report_markdown"]

#: batch -> method -> (orders × steps) accuracies; "library" and "NCM" have one column.
Tables = Mapping[int, Mapping[str, np.ndarray]]


#: What the library's row of a batch carries besides its accuracy (orders × 1 each): its size
#: after the batch was merged, the batch's CPU seconds, the process's memory after it (MB).
EXTRAS = {"size": "library", "seconds": "seconds", "memory_mb": "memory_mb"}


def tables(rows: Sequence[Mapping[str, Any]]) -> dict[int, dict[str, np.ndarray]]:
    """Batch -> method -> (orders × steps) accuracies, orders in order; and the library row's
    :data:`EXTRAS` (orders × 1 each) where the rows have them."""
    out: dict[int, dict[str, dict[int, dict[int, float]]]] = {}
    extras: dict[str, dict[int, dict[int, float]]] = {k: {} for k in [*EXTRAS, "learned_with"]}
    for r in rows:
        b, o = int(r["batch"]), int(r["order"])
        out.setdefault(b, {}).setdefault(str(r["method"]), {}).setdefault(o, {})[int(r["step"])] = (
            float(r["accuracy"])
        )
        if r["method"] == "library":
            for key, column in EXTRAS.items():
                if r.get(column) not in (None, ""):
                    extras[key].setdefault(b, {})[o] = float(r[column])
        elif r["method"] == "APTKT" and int(r["step"]) == 0:
            # The library the batch was learned with (before it was merged in).
            extras["learned_with"].setdefault(b, {})[o] = float(r["library"])
    result: dict[int, dict[str, np.ndarray]] = {}
    for b in sorted(out):
        result[b] = {method: curve_matrix(per_order) for method, per_order in out[b].items()}
        for key, per_batch in extras.items():
            if b in per_batch:
                result[b][key] = np.array([[per_batch[b][o]] for o in sorted(per_batch[b])])
    return result


def _size(m: Mapping[str, np.ndarray], key: str = "size") -> int:
    """The library's size after the batch (``size``) or before it (``learned_with``)."""
    return int(np.nanmean(m[key])) if key in m else 0


def _paired(a: np.ndarray, b: np.ndarray) -> Estimate:
    return estimate(a - b, units=list(range(len(a))), unit_name="order")


def _last(values: np.ndarray) -> int:
    return int(values.shape[1] - 1)


def checks(c: Tables) -> list[Check]:
    """The gains of the last batch — learned with the largest library — at least the first's,
    at one observation per object and at the end of the budget (means over orders, paired;
    with fewer than three batches, none); after the last batch, the library at least the
    nearest-class-mean rule."""
    out = []
    batches = sorted(c)
    if len(batches) >= 3:
        first, final = c[batches[0]], c[batches[-1]]
        for when, step in (("one-shot", lambda m: 0), ("end-of-budget", _last)):
            k0, k1 = step(first["APTKT"]), step(final["APTKT"])
            early = _paired(first["APTKT"][:, k0], first["baseline"][:, k0])
            late = _paired(final["APTKT"][:, k1], final["baseline"][:, k1])
            diff = _paired(
                final["APTKT"][:, k1] - final["baseline"][:, k1],
                first["APTKT"][:, k0] - first["baseline"][:, k0],
            )
            out.append(
                Check(
                    f"the {when} gain over the baseline does not shrink as the library grows: "
                    f"batch {batches[-1]} (learned with {_size(final, 'learned_with')} objects) "
                    f"at least batch {batches[0]} ({_size(first, 'learned_with')})",
                    f"{pp(late.mean)} against {pp(early.mean)} (difference {ci(diff, cell=True)})",
                    late.mean >= early.mean - ROUNDING,
                )
            )
    if batches:
        last = batches[-1]
        m = c[last]
        d = _paired(m["library"][:, 0], m["NCM"][:, 0])
        out.append(
            Check(
                f"after the last batch the library ({_size(m)} objects) is at least as accurate as "
                "the nearest class mean in its metric on the same observations",
                f"{np.nanmean(m['library']):.3f} against {np.nanmean(m['NCM']):.3f} "
                f"({ci(d, cell=True)})",
                d.mean >= -ROUNDING,
                REFERENCE,
            )
        )
    return out


def summary(c: Tables) -> dict[str, Any]:
    out: dict[str, Any] = {}
    extras = {*EXTRAS, "learned_with"}
    for b, m in c.items():
        last = _last(m["APTKT"])
        out[str(b)] = {
            "library_size": float(np.nanmean(m["size"])) if "size" in m else None,
            "learned_with": float(np.nanmean(m["learned_with"])) if "learned_with" in m else None,
            "cpu_seconds": float(np.nanmean(m["seconds"])) if "seconds" in m else None,
            "memory_mb": float(np.nanmax(m["memory_mb"])) if "memory_mb" in m else None,
            "mean": {k: np.nanmean(v, axis=0).tolist() for k, v in m.items() if k not in extras},
            "gain_one_shot": _paired(m["APTKT"][:, 0], m["baseline"][:, 0]).as_dict(),
            "gain_last_step": _paired(m["APTKT"][:, last], m["baseline"][:, last]).as_dict(),
            "library_vs_ncm": _paired(m["library"][:, 0], m["NCM"][:, 0]).as_dict(),
        }
    return out


def plot(c: Tables) -> Any:
    """Against the size of the library each batch was learned with (a log scale for a long
    stream): APTKT's gain over the baseline at one observation per object and at the end of
    the budget (95 % intervals over orders); the grown library's accuracy on every object it
    holds, and the nearest class mean's; and each batch's CPU seconds and the memory after it."""
    batches = sorted(c)
    costs = all("seconds" in c[b] for b in batches)
    fig, axes = figure(1, 3 if costs else 2, figsize=(15.0 if costs else 10.0, 4.4), squeeze=False)
    gain_ax, library_ax = axes[0][0], axes[0][1]
    x = np.array([_size(c[b], "learned_with") or b for b in batches], dtype=float)
    long = len(batches) > 6
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
        shift = x * (1 + 0.02 * (offset - 0.5)) if long else x + 0.06 * (offset - 0.5)
        gain_ax.errorbar(shift, mean, yerr=np.nan_to_num(err), capsize=3, label=label, **look)
    gain_ax.axhline(0, color="0.3", lw=1)
    gain_ax.set_ylabel("APTKT − baseline (pp, 95 % intervals)")
    gain_ax.set_title("learning each batch")
    after = np.array([_size(c[b]) or b for b in batches], dtype=float)
    for method, look in (
        ("library", {"color": "C3", "marker": "o", "ls": "-"}),
        ("NCM", {"color": "0.4", "marker": "D", "ls": ":"}),
    ):
        bands = [mean_band(c[b][method]) for b in batches]
        mean = np.array([bd[0][0] for bd in bands])
        low = np.array([bd[1][0] for bd in bands])
        high = np.array([bd[2][0] for bd in bands])
        library_ax.errorbar(
            after,
            mean,
            yerr=np.nan_to_num([mean - low, high - mean]),
            capsize=3,
            label="the library's model" if method == "library" else "nearest class mean",
            **look,
        )
    lowest = min(float(np.nanmin(c[b][m])) for b in batches for m in ("library", "NCM"))
    library_ax.set_ylim(max(0.0, lowest - 0.1), 1.0)
    library_ax.set_ylabel("accuracy on every object it holds")
    library_ax.set_title("the grown library")
    library_ax.set_xlabel("objects in the library after the batch")
    gain_ax.set_xlabel("objects in the library the batch was learned with")
    if costs:
        cost_ax = axes[0][2]
        seconds = np.array([float(np.nanmean(c[b]["seconds"])) for b in batches])
        cost_ax.plot(after, seconds, "o-", color="C1", label="CPU seconds per batch")
        cost_ax.set_ylabel("CPU seconds (learning and merging the batch)")
        memory = cost_ax.twinx()
        resident = np.array([float(np.nanmax(c[b]["memory_mb"])) for b in batches])
        memory.plot(after, resident, "s--", color="C4", label="memory after the batch (MB)")
        memory.set_ylabel("the process's memory after the batch (MB)")
        cost_ax.set_title("cost")
        cost_ax.set_xlabel("objects in the library after the batch")
        handles = cost_ax.get_legend_handles_labels()
        more = memory.get_legend_handles_labels()
        cost_ax.legend(
            handles[0] + more[0], handles[1] + more[1], loc="upper left", fontsize="small"
        )
    for ax in axes[0]:
        if long:
            ax.set_xscale("log")
        elif ax is gain_ax:
            ax.set_xticks(x)
        ax.grid(alpha=0.3)
        if ax is not axes[0][-1] or not costs:
            ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def report_markdown(c: Tables, head: Mapping[str, Any], found: Sequence[Check]) -> str:
    batches = sorted(c)
    if head.get("stream"):
        sizes = head.get("batch_sizes") or []
        design = (
            f"A stream of {head['stream']} synthetic objects per order, drawn from the "
            f"population fitted on the table's objects (their within-object noise and "
            f'between-object spread; docs/method.md, "A library of thousands"), '
            f"{head['orders']} orders (each its own stream). The first {head['batch']} "
            f"objects are the starting library (the first half of their trials); then "
            f"batches of {min(sizes, default=head['batch'])} to {max(sizes, default=head['batch'])} "
            f"objects, each as large as the library: the first {head['batch']} of a batch are "
            f"learned — APTKT with the whole library, the baseline with nothing, one "
            f"observation per object then {head['budget']} actively chosen — and merged with "
            "the observations APTKT made, the batch's other objects with the first half of "
            "their trials; the library is refitted."
        )
    else:
        design = (
            f"{head['objects']} objects, action(s) {', '.join(head['actions'])}, {head['orders']} "
            f"random orders. In each, the first {head['batch']} objects are the starting library "
            "(the first half of their trials); then each batch of "
            f"{head['batch']} is learned — APTKT with the whole library, the baseline with "
            f"nothing, one observation per object then {head['budget']} actively chosen — and "
            "the observations APTKT made are merged into the library, which is refitted."
        )
    lines = [
        f"# Lifelong benchmark: {head['table']}",
        "",
        f"Command: `{head['command']}`  ",
        f"aptkt {head['software_version']}; {head['seconds']:.0f} s on {head['jobs']} "
        f"process(es); {head['date']}.",
        "",
        design + " Accuracy on the held-out second half of the trials; gains paired by order, "
        "95 % Student-t intervals over orders.",
        "",
        "## Checks",
        "",
        checks_table(found, unit=f"{head['orders']} orders"),
        "",
        "## Per batch",
        "",
    ]
    rows = []
    costs = all("seconds" in c[b] for b in batches)
    n_orders = f"95 % CI over {head['orders']} orders"
    for b in batches:
        m = c[b]
        last = _last(m["APTKT"])
        mean = {k: np.nanmean(v, axis=0) for k, v in m.items()}
        row = [
            str(b),
            str(_size(m, "learned_with") or ""),
            f"{mean['baseline'][0]:.3f} → {mean['baseline'][last]:.3f}",
            f"{mean['APTKT'][0]:.3f} → {mean['APTKT'][last]:.3f}",
            ci(_paired(m["APTKT"][:, 0], m["baseline"][:, 0]), cell=True),
            ci(_paired(m["APTKT"][:, last], m["baseline"][:, last]), cell=True),
            str(_size(m) or ""),
            f"{mean['library'][0]:.3f} / {mean['NCM'][0]:.3f}",
            ci(_paired(m["library"][:, 0], m["NCM"][:, 0]), cell=True),
        ]
        if costs:
            row += [f"{mean['seconds'][0]:.1f}", f"{float(np.nanmax(m['memory_mb'])):.0f}"]
        rows.append(row)
    last = _last(c[batches[0]]["APTKT"]) if batches else 0
    header = [
        "batch",
        "learned with (objects)",
        f"baseline step 0 → {last}",
        f"APTKT step 0 → {last}",
        f"APTKT − baseline, step 0 ({n_orders})",
        f"APTKT − baseline, step {last} ({n_orders})",
        "library size after",
        "library / nearest class mean",
        f"library − nearest class mean ({n_orders})",
    ]
    if costs:
        header += ["CPU s per batch", "memory after (MB)"]
    lines += [
        markdown_table(header, rows),
        "",
        "Plot: `lifelong.png` / `.svg`. Every order's numbers: `results.csv`; the summary: "
        "`summary.json`.",
        "",
    ]
    return "\n".join(lines)
