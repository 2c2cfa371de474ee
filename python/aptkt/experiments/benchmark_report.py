"""The real-data benchmark's analysis: paired gains with 95 % intervals, the checks the method
must pass on real data, plots and report.md (see :mod:`aptkt.experiments.benchmark`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.experiments.aggregate import Estimate, estimate, mean_band
from aptkt.experiments.noise_profile import NoiseProfile
from aptkt.experiments.plots import curve_styles, figure
from aptkt.experiments.report import ci, markdown_table, pp

__all__ = ["Check", "curves", "checks", "summary", "plot", "report_markdown"]

#: Steps the tables show (those within the budget).
TABLE_STEPS = (0, 1, 2, 3, 5, 10, 20, 40)
#: The largest fall of a mean curve from one step to the next that still counts as "not
#: unlearning" (accuracy is a mean over held-out observations; a fall this small is noise).
UNLEARNING_TOLERANCE = 0.01
#: APTKT's gain over the baseline at one observation per object the paper reports (Fig. 7).
PAPER_ONE_SHOT_GAIN = 0.10
#: How far below the baseline APTKT may be at any step with the least similar priors.
NO_HARM_TOLERANCE = 0.01
METHOD_ORDER = ("baseline", "control", "APTKT", "APTKT+aux")


def curves(rows: Sequence[Mapping[str, Any]]) -> dict[str, dict[str, np.ndarray]]:
    """Prior choice -> method -> (groups × steps) accuracies, groups in order; "1-NN" has one
    column (step 0)."""
    out: dict[str, dict[str, dict[int, dict[int, float]]]] = {}
    for r in rows:
        per = out.setdefault(str(r["priors"]), {}).setdefault(str(r["method"]), {})
        per.setdefault(int(r["group"]), {})[int(r["step"])] = float(r["accuracy"])
    result: dict[str, dict[str, np.ndarray]] = {}
    for choice, methods in out.items():
        result[choice] = {}
        for method, groups in methods.items():
            order = sorted(groups)
            width = max(max(g) for g in groups.values()) + 1
            values = np.full((len(order), width), np.nan)
            for i, g in enumerate(order):
                for step, v in groups[g].items():
                    values[i, step] = v
            result[choice][method] = values
    return result


def _paired(a: np.ndarray, b: np.ndarray) -> Estimate:
    """The mean difference over groups (one value each) with its 95 % interval."""
    return estimate(a - b, units=list(range(len(a))), unit_name="group")


@dataclass(frozen=True)
class Check:
    """One property the method must have on real data, judged from the runs."""

    claim: str
    measured: str
    holds: bool


def _largest_fall(values: np.ndarray) -> tuple[float, int]:
    mean = np.nanmean(values, axis=0)
    if mean.size < 2:
        return 0.0, 0
    falls = np.diff(mean)
    k = int(np.argmin(falls))
    return float(-falls[k]), k + 1


def checks(c: Mapping[str, Mapping[str, np.ndarray]]) -> list[Check]:
    """The targets on real data: a one-shot gain of the paper's size with random priors, at
    least the 1-NN reference; never below the baseline with the least similar priors; the
    auxiliary features never below plain APTKT; no method's mean curve falling by more than
    :data:`UNLEARNING_TOLERANCE` from one step to the next."""
    out = []
    if "random" in c:
        r = c["random"]
        gain = _paired(r["APTKT"][:, 0], r["baseline"][:, 0])
        out.append(
            Check(
                f"random priors: APTKT ≥ baseline + {100 * PAPER_ONE_SHOT_GAIN:.0f} pp at one "
                "observation per object, its interval above +5 pp",
                ci(gain),
                gain.mean >= PAPER_ONE_SHOT_GAIN and gain.low > 0.05,
            )
        )
        nn = _paired(r["APTKT"][:, 0], r["1-NN"][:, 0])
        out.append(
            Check(
                "random priors: APTKT at one shot at least the 1-nearest-neighbour rule in its "
                "own feature space",
                ci(nn),
                nn.mean >= 0,
            )
        )
    if "farthest" in c:
        f = c["farthest"]
        d = f["APTKT"] - f["baseline"]
        mean = np.nanmean(d, axis=0)
        k = int(np.argmin(mean))
        out.append(
            Check(
                f"least similar priors: APTKT never below the baseline by more than "
                f"{100 * NO_HARM_TOLERANCE:.0f} pp at any step",
                f"lowest {pp(mean[k])} at step {k} ({ci(_paired(f['APTKT'][:, k], f['baseline'][:, k]))})",
                bool(mean[k] >= -NO_HARM_TOLERANCE),
            )
        )
    worst = None
    for choice, methods in c.items():
        if "APTKT+aux" in methods:
            d = np.nanmean(methods["APTKT+aux"] - methods["APTKT"], axis=0)
            k = int(np.argmin(d))
            if worst is None or d[k] < worst[0]:
                low = _paired(methods["APTKT+aux"][:, k], methods["APTKT"][:, k])
                worst = (float(d[k]), k, choice, low)
    if worst is not None:
        out.append(
            Check(
                "APTKT with auxiliary features never below plain APTKT (mean, any step, any "
                "prior choice)",
                f"lowest {pp(worst[0])} at step {worst[1]}, {worst[2]} priors ({ci(worst[3])})",
                worst[0] >= 0,
            )
        )
    falls = []
    for choice, methods in c.items():
        for method in METHOD_ORDER:
            if method in methods:
                fall, step = _largest_fall(methods[method])
                falls.append((fall, step, method, choice))
    if falls:
        fall, step, method, choice = max(falls)
        out.append(
            Check(
                f"no method unlearns: no mean curve falls by more than "
                f"{100 * UNLEARNING_TOLERANCE:.0f} pp from one step to the next",
                f"largest fall {100 * fall:.1f} pp ({method}, {choice} priors, step {step})",
                fall <= UNLEARNING_TOLERANCE,
            )
        )
    return out


def summary(c: Mapping[str, Mapping[str, np.ndarray]]) -> dict[str, Any]:
    """Per prior choice: each method's mean curve, and each method's paired gain over the
    baseline (and the 1-NN reference) with its interval at every step."""
    out: dict[str, Any] = {}
    for choice, methods in c.items():
        base = methods["baseline"]
        entry: dict[str, Any] = {"groups": int(base.shape[0]), "mean": {}, "gain": {}}
        for method, values in methods.items():
            entry["mean"][method] = np.nanmean(values, axis=0).tolist()
            if method in ("baseline", "1-NN"):
                continue
            entry["gain"][method] = [
                _paired(values[:, k], base[:, k]).as_dict() for k in range(values.shape[1])
            ]
        if "1-NN" in methods:
            entry["gain"]["APTKT vs 1-NN"] = _paired(
                methods["APTKT"][:, 0], methods["1-NN"][:, 0]
            ).as_dict()
        out[choice] = entry
    return out


_TITLES = {
    "random": "random priors",
    "nearest": "the most similar priors",
    "farthest": "the least similar priors",
}


def plot(c: Mapping[str, Mapping[str, np.ndarray]], chance: float) -> Any:
    """Top: each method's mean accuracy per prior choice with its 95 % band (clipped to
    [0, 1]) and the 1-NN reference at step 0; bottom: each method's paired gain over the
    baseline with its band."""
    from matplotlib.ticker import MaxNLocator  # matplotlib is imported when a plot is made

    choices = sorted(c, key=lambda k: list(_TITLES).index(k) if k in _TITLES else 99)
    fig, axes = figure(2, len(choices), figsize=(5.0 * len(choices), 7.6), squeeze=False)
    for j, choice in enumerate(choices):
        methods = c[choice]
        top, bottom = axes[0, j], axes[1, j]
        steps = np.arange(methods["baseline"].shape[1])
        styles = curve_styles((m for m in METHOD_ORDER if m in methods), len(steps))
        for method, look in styles.items():
            colour = look["color"]
            mean, low, high = mean_band(methods[method])
            top.plot(steps, mean, label=method, **look)
            top.fill_between(
                steps, np.clip(low, 0, 1), np.clip(high, 0, 1), color=colour, alpha=0.15, lw=0
            )
            if method != "baseline":
                d_mean, d_low, d_high = mean_band(methods[method] - methods["baseline"])
                bottom.plot(steps, 100 * d_mean, label=f"{method} − baseline", **look)
                bottom.fill_between(
                    steps, 100 * d_low, 100 * d_high, color=colour, alpha=0.15, lw=0
                )
        if "1-NN" in methods:
            nn = methods["1-NN"][:, 0]
            top.errorbar(
                [0],
                [nn.mean()],
                yerr=[
                    [nn.mean() - mean_band(nn[:, None])[1][0]],
                    [mean_band(nn[:, None])[2][0] - nn.mean()],
                ],
                fmt="D",
                color="black",
                ms=6,
                capsize=3,
                label="1-NN (prior's metric)",
            )
        top.axhline(chance, color="0.5", ls="--", lw=1, label=f"chance ({chance:.2f})")
        top.set_ylim(0, 1.0)
        top.set_title(f"{_TITLES.get(choice, choice)} ({methods['baseline'].shape[0]} groups)")
        top.set_ylabel("accuracy on held-out trials")
        top.grid(alpha=0.3)
        bottom.axhline(0, color="0.3", lw=1)
        for ax in (top, bottom):
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        bottom.set_xlabel("observations chosen after one of each new object")
        bottom.set_ylabel("gain over the baseline (pp)")
        bottom.grid(alpha=0.3)
        if j == 0:
            top.legend(loc="lower right", fontsize="small")
            bottom.legend(loc="upper right", fontsize="small", title="bands: 95 % intervals")
    fig.tight_layout()
    return fig


def report_markdown(
    c: Mapping[str, Mapping[str, np.ndarray]],
    head: Mapping[str, Any],
    found: Sequence[Check],
    profiles: Sequence[NoiseProfile] = (),
) -> str:
    """report.md: the set-up, each check with its verdict, the curves and the gains, and how
    the data's noise looks."""
    lines = [
        f"# Real-data benchmark: {head['table']}",
        "",
        f"Command: `{head['command']}`  ",
        f"aptkt {head['software_version']}; {head['seconds']:.0f} s on {head['jobs']} process(es); "
        f"{head['date']}.",
        "",
        f"{head['objects']} objects, action(s) {', '.join(head['actions'])}. Each of "
        f"{head['groups']} groups draws {head['new']} new objects and {head['priors']} prior "
        "objects three ways (at random, the most and the least similar to the new ones: the "
        "distance between object means in units of the pooled within-object noise). The first "
        "half of every object's trials builds the prior and is the pool learned from; the second "
        "half is held out. Step 0: one observation of each new object per action; then "
        f"{head['budget']} actively chosen ones. Gains are paired by group; intervals are 95 % "
        "Student-t intervals over groups.",
        "",
        "## Checks",
        "",
        markdown_table(
            ["", "claim", "measured"],
            [["holds" if k.holds else "**fails**", k.claim, k.measured] for k in found],
        ),
        "",
    ]
    for choice in sorted(c, key=lambda k: list(_TITLES).index(k) if k in _TITLES else 99):
        methods = c[choice]
        n_steps = methods["baseline"].shape[1]
        steps = [s for s in TABLE_STEPS if s < n_steps]
        lines += [f"## {_TITLES.get(choice, choice).capitalize()}", ""]
        rows = []
        for method in (*METHOD_ORDER, "1-NN"):
            if method not in methods:
                continue
            mean = np.nanmean(methods[method], axis=0)
            rows.append([method] + [f"{mean[s]:.3f}" if s < mean.size else "" for s in steps])
        lines += [markdown_table(["mean accuracy", *(f"step {s}" for s in steps)], rows), ""]
        rows = []
        for method in METHOD_ORDER[1:]:
            if method in methods:
                rows.append(
                    [f"{method} − baseline"]
                    + [ci(_paired(methods[method][:, s], methods["baseline"][:, s])) for s in steps]
                )
        if "APTKT+aux" in methods:
            rows.append(
                ["APTKT+aux − APTKT"]
                + [ci(_paired(methods["APTKT+aux"][:, s], methods["APTKT"][:, s])) for s in steps]
            )
        lines += [markdown_table(["paired gain", *(f"step {s}" for s in steps)], rows), ""]
    if profiles:
        lines += [
            "## How the data's noise looks",
            "",
            "Per action and modality (`aptkt.experiments.noise_profile`): separation — the "
            "spread of the object means in units of the within-object noise; drift — how far "
            "each object's observations move from the first half of its trials to the second, "
            "against stationary noise (1: none); heterogeneity — how much the noise differs "
            "between objects, against equal noise (1: the same for every object).",
            "",
            markdown_table(
                ["action", "modality", "columns", "separation", "drift", "heterogeneity"],
                [
                    [
                        p.action,
                        p.modality,
                        p.columns,
                        f"{p.separation:.2f}",
                        f"{p.drift:.2f}",
                        f"{p.heterogeneity:.2f}",
                    ]
                    for p in profiles
                ],
            ),
            "",
        ]
    lines += [
        "Plots: `benchmark.png` / `.svg` (top: mean accuracy with 95 % bands, the 1-NN "
        "reference at step 0; bottom: gains over the baseline). Every group's curves: "
        "`results.csv`; the numbers above: `summary.json`.",
        "",
    ]
    return "\n".join(lines)
