"""The real-data benchmark's analysis: paired gains with 95 % intervals, the checks the method
must pass on real data, plots and report.md (see :mod:`aptkt.experiments.benchmark`).

Results are read as ``curves[library size][prior choice][method]``: a (groups × steps) array
of accuracies, groups in order ("1-NN" and "1-NN shrunk" have one column, step 0)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aptkt.errors import InvalidInputError
from aptkt.experiments.aggregate import Estimate, estimate, mean_band
from aptkt.experiments.noise_profile import NoiseProfile
from aptkt.experiments.plots import curve_styles, figure
from aptkt.experiments.report import ci, markdown_table, pp

__all__ = [
    "Check",
    "Curves",
    "curves",
    "checks",
    "summary",
    "plot",
    "plot_library",
    "report_markdown",
]

#: Steps the tables show (those within the budget).
TABLE_STEPS = (0, 1, 2, 3, 5, 10, 20, 40)
#: The largest fall of a mean curve from one step to the next that still counts as "not
#: unlearning" (accuracy is a mean over held-out observations; a fall this small is noise).
UNLEARNING_TOLERANCE = 0.01
#: APTKT's gain over the baseline at one observation per object the paper reports (Fig. 7).
PAPER_ONE_SHOT_GAIN = 0.10
#: How far below the baseline APTKT may be at any step (mean over groups).
NO_HARM_TOLERANCE = 0.01
#: How far below the control APTKT may be at any step — a transfer must not cost — and APTKT
#: with auxiliary features below plain APTKT: an addition must not cost either.
TRANSFER_COST_TOLERANCE = 0.005
#: How much APTKT must gain over its own one-shot accuracy by the end of the budget.
KEEPS_LEARNING = 0.03
#: How much smaller the one-shot gain of the largest library may be than the smallest's.
GROWTH_TOLERANCE = 0.01
METHOD_ORDER = ("baseline", "control", "APTKT", "APTKT+aux")
REFERENCES = ("1-NN", "1-NN shrunk")
_REFERENCE_LABELS = {
    "1-NN": "1-NN (prior's metric)",
    "1-NN shrunk": "1-NN (shrunk covariance)",
}

#: Accuracies are means of 0/1 outcomes: a claim at a bound holds up to rounding.
ROUNDING = 1e-9

#: library size -> prior choice -> method -> (groups × steps) accuracies.
Curves = Mapping[int, Mapping[str, Mapping[str, np.ndarray]]]


def curves(
    rows: Sequence[Mapping[str, Any]], value: str = "accuracy"
) -> dict[int, dict[str, dict[str, np.ndarray]]]:
    """Library size -> prior choice -> method -> (groups × steps) accuracies (or another
    ``value`` of the rows: "estimated", the learners' own estimates; rows without it are left
    out), groups in order. Rows without a library size (results written before it existed)
    count as one library."""
    out: dict[int, dict[str, dict[str, dict[int, dict[int, float]]]]] = {}
    for r in rows:
        if r.get(value) in (None, ""):
            continue
        size = int(r.get("library") or 0)
        per = out.setdefault(size, {}).setdefault(str(r["priors"]), {})
        per.setdefault(str(r["method"]), {}).setdefault(int(r["group"]), {})[int(r["step"])] = (
            float(r[value])
        )
    return {
        size: {
            choice: {method: curve_matrix(groups) for method, groups in methods.items()}
            for choice, methods in out[size].items()
        }
        for size in sorted(out)
    }


def curve_matrix(per_unit: Mapping[int, Mapping[int, float]]) -> np.ndarray:
    """(units × steps) values from unit -> step -> value, units in order (groups, orders); a
    step a unit never reached is NaN."""
    order = sorted(per_unit)
    width = max(max(steps) for steps in per_unit.values()) + 1
    values = np.full((len(order), width), np.nan)
    for i, unit in enumerate(order):
        for step, v in per_unit[unit].items():
            values[i, step] = v
    return values


def _paired(a: np.ndarray, b: np.ndarray) -> Estimate:
    """The mean difference over groups (one value each) with its 95 % interval."""
    return estimate(a - b, units=list(range(len(a))), unit_name="group")


#: What a check is. An invariant must hold on any sensor's data: a failure means the method or
#: the software misbehaved. A reference figure is what the paper and the BioTac set showed; on
#: another sensor's data it may or may not be reached, and neither is a fault.
INVARIANT, REFERENCE = "invariant", "reference"
CHECK_KINDS = (INVARIANT, REFERENCE)


@dataclass(frozen=True)
class Check:
    """One property judged from the runs: an invariant (``holds``/``fails``) or a reference
    figure (``reached``/``not reached``)."""

    claim: str
    measured: str
    holds: bool
    kind: str = INVARIANT

    def __post_init__(self) -> None:
        if self.kind not in CHECK_KINDS:
            raise InvalidInputError(f"a check is one of {CHECK_KINDS}, not {self.kind!r}")

    @property
    def verdict(self) -> str:
        if self.kind == REFERENCE:
            return "reached" if self.holds else "not reached"
        return "holds" if self.holds else "fails"

    def as_dict(self) -> dict[str, Any]:
        return {
            "claim": self.claim,
            "measured": self.measured,
            "holds": self.holds,
            "kind": self.kind,
            "verdict": self.verdict,
        }


def failed_checks(checks: Sequence[Mapping[str, Any]], kinds: Sequence[str]) -> list[Mapping]:
    """The checks of a summary (``as_dict``) of the given kinds that do not hold; a summary
    written before checks had kinds counts every check as an invariant."""
    return [c for c in checks if not c["holds"] and c.get("kind", INVARIANT) in kinds]


def checks_table(found: Sequence[Check], unit: str = "") -> str:
    """The report's checks: first what must hold on any data, then the reference figures."""
    parts = []
    note = f" Intervals: 95 %, over {unit}." if unit else ""
    for kind, title, intro in (
        (
            INVARIANT,
            "### What must hold on any data",
            "A failure here means the method misbehaved on this data." + note,
        ),
        (
            REFERENCE,
            "### Reference figures",
            "What the paper and the public BioTac set showed. Another sensor's data may or may "
            "not reach them; not reaching one is no fault.",
        ),
    ):
        rows = [k for k in found if k.kind == kind]
        if not rows:
            continue
        verdict = (
            (lambda k: k.verdict)
            if kind == REFERENCE
            else (lambda k: "holds" if k.holds else "**fails**")
        )
        parts += [
            title,
            "",
            intro,
            "",
            markdown_table(
                ["", "claim", "measured"], [[verdict(k), k.claim, k.measured] for k in rows]
            ),
            "",
        ]
    return "\n".join(parts).rstrip("\n")


def announce_checks(found: Sequence[Check], say: Callable[[str], None]) -> int:
    """One line per check on the console, the invariants first; returns how many invariants
    hold (the reference figures are reported, not counted)."""
    for kind in CHECK_KINDS:
        for k in found:
            if k.kind == kind:
                say(
                    f"  {k.verdict.upper() if k.verdict == 'fails' else k.verdict}: {k.claim} — {k.measured}"
                )
    return sum(k.holds for k in found if k.kind == INVARIANT)


def checks_line(found: Sequence[Check]) -> str:
    """``5 of 5 checks hold; 2 of 4 reference figures reached``."""
    inv = [k for k in found if k.kind == INVARIANT]
    ref = [k for k in found if k.kind == REFERENCE]
    text = f"{sum(k.holds for k in inv)} of {len(inv)} checks hold" if inv else "no check applies"
    if ref:
        text += f"; {sum(k.holds for k in ref)} of {len(ref)} reference figures reached"
    return text


def _largest_fall(values: np.ndarray) -> tuple[float, int]:
    mean = np.nanmean(values, axis=0)
    if mean.size < 2:
        return 0.0, 0
    falls = np.diff(mean)
    k = int(np.argmin(falls))
    return float(-falls[k]), k + 1


def _label(size: int, choice: str, sizes: int) -> str:
    """How a check or section names its runs: the prior choice, and the library size when
    several are compared."""
    what = {"random": "random", "nearest": "most similar", "farthest": "least similar"}
    base = f"{what.get(choice, choice)} priors"
    return f"{size} {base}" if sizes > 1 and size else base


def _never_below(a: np.ndarray, b: np.ndarray) -> tuple[float, int, Estimate]:
    """The lowest mean of a − b over the steps, its step and its paired interval."""
    mean = np.nanmean(a - b, axis=0)
    k = int(np.argmin(mean))
    return float(mean[k]), k, _paired(a[:, k], b[:, k])


def _library_checks(size: int, choice: str, m: Mapping[str, np.ndarray], sizes: int) -> list[Check]:
    """The checks of one library size and prior choice."""
    who = _label(size, choice, sizes)
    out = []
    if choice == "random":
        gain = _paired(m["APTKT"][:, 0], m["baseline"][:, 0])
        out.append(
            Check(
                f"{who}: APTKT ≥ baseline + {100 * PAPER_ONE_SHOT_GAIN:.0f} pp at one "
                "observation per object, its interval above +5 pp",
                ci(gain, cell=True),
                gain.mean >= PAPER_ONE_SHOT_GAIN - ROUNDING and gain.low > 0.05,
                REFERENCE,
            )
        )
        for ref, what in (
            ("1-NN", "the 1-nearest-neighbour rule in its own feature space"),
            ("1-NN shrunk", "the 1-nearest-neighbour rule in the priors' shrunk covariance"),
        ):
            if ref in m:
                nn = _paired(m["APTKT"][:, 0], m[ref][:, 0])
                out.append(
                    Check(
                        f"{who}: APTKT at one shot at least {what}",
                        ci(nn, cell=True),
                        nn.mean >= -ROUNDING,
                        REFERENCE,
                    )
                )
    if choice in ("random", "farthest"):
        low, k, at = _never_below(m["APTKT"], m["baseline"])
        out.append(
            Check(
                f"{who}: APTKT never below the baseline by more than "
                f"{100 * NO_HARM_TOLERANCE:.0f} pp at any step",
                f"lowest {pp(low)} at step {k} ({ci(at, cell=True)})",
                low >= -NO_HARM_TOLERANCE - ROUNDING,
            )
        )
    if choice == "random":
        if "control" in m:
            low, k, at = _never_below(m["APTKT"], m["control"])
            out.append(
                Check(
                    f"{who}: a transfer never costs — APTKT never below the control by more "
                    f"than {100 * TRANSFER_COST_TOLERANCE:.1f} pp at any step",
                    f"lowest {pp(low)} at step {k} ({ci(at, cell=True)})",
                    low >= -TRANSFER_COST_TOLERANCE - ROUNDING,
                )
            )
        last = m["APTKT"].shape[1] - 1
        if last > 0:
            a, b = np.nanmean(m["APTKT"], axis=0), np.nanmean(m["baseline"], axis=0)
            rise = a[last] - a[0]
            out.append(
                Check(
                    f"{who}: APTKT at the end of the budget (step {last}) at least the baseline",
                    f"{pp(a[last] - b[last])} against the baseline",
                    bool(a[last] >= b[last] - ROUNDING),
                )
            )
            out.append(
                Check(
                    f"{who}: APTKT keeps learning — at step {last} "
                    f"{100 * KEEPS_LEARNING:.0f} pp above its own step 0",
                    f"{pp(rise)} since step 0",
                    bool(rise >= KEEPS_LEARNING - ROUNDING),
                    REFERENCE,
                )
            )
    return out


def checks(c: Curves) -> list[Check]:
    """The targets on real data, per library size: with random priors a one-shot gain of the
    paper's size, at least both nearest-neighbour references, never below the baseline, a
    transfer that never costs against the control, and learning that goes on; never below the
    baseline with the least similar priors; then, over every library and choice, the auxiliary
    features never below plain APTKT and no method's mean curve falling by more than
    :data:`UNLEARNING_TOLERANCE` from one step to the next; and with several library sizes, a
    one-shot gain that does not shrink as the library grows."""
    out: list[Check] = []
    sizes = len(c)
    for size, per_choice in c.items():
        for choice in sorted(per_choice, key=_choice_order):
            out += _library_checks(size, choice, per_choice[choice], sizes)
    random = {size: per["random"] for size, per in c.items() if "random" in per}
    if len(random) > 1:
        small, large = min(random), max(random)
        g_small = _paired(random[small]["APTKT"][:, 0], random[small]["baseline"][:, 0])
        g_large = _paired(random[large]["APTKT"][:, 0], random[large]["baseline"][:, 0])
        out.append(
            Check(
                f"the one-shot gain does not shrink as the library grows: with {large} random "
                f"priors at least the gain with {small} − {100 * GROWTH_TOLERANCE:.0f} pp",
                f"{pp(g_large.mean)} with {large}, {pp(g_small.mean)} with {small}",
                g_large.mean >= g_small.mean - GROWTH_TOLERANCE - ROUNDING,
            )
        )
    worst = None
    for size, per_choice in c.items():
        for choice, methods in per_choice.items():
            if AUX in methods:
                low, k, at = _never_below(methods[AUX], methods["APTKT"])
                if worst is None or low < worst[0]:
                    worst = (low, k, _label(size, choice, sizes), at)
    if worst is not None:
        out.append(
            Check(
                "APTKT with auxiliary features never below plain APTKT by more than "
                f"{100 * TRANSFER_COST_TOLERANCE:.1f} pp (mean, any step, any library and prior "
                "choice)",
                f"lowest {pp(worst[0])} at step {worst[1]}, {worst[2]} ({ci(worst[3], cell=True)})",
                worst[0] >= -TRANSFER_COST_TOLERANCE - ROUNDING,
            )
        )
    falls = []
    for size, per_choice in c.items():
        for choice, methods in per_choice.items():
            for method in METHOD_ORDER:
                if method in methods:
                    fall, step = _largest_fall(methods[method])
                    falls.append((fall, step, method, _label(size, choice, sizes)))
    if falls:
        fall, step, method, who = max(falls)
        out.append(
            Check(
                f"no method unlearns: no mean curve falls by more than "
                f"{100 * UNLEARNING_TOLERANCE:.0f} pp from one step to the next",
                f"largest fall {100 * fall:.1f} pp ({method}, {who}, step {step})",
                fall <= UNLEARNING_TOLERANCE + ROUNDING,
            )
        )
    return out


def summary(c: Curves) -> dict[str, Any]:
    """Per library size and prior choice: each method's mean curve, and each method's paired
    gain over the baseline with its interval at every step (and APTKT against the control and
    the nearest-neighbour references at step 0)."""
    out: dict[str, Any] = {}
    for size, per_choice in c.items():
        entry_size: dict[str, Any] = {}
        for choice, methods in per_choice.items():
            base = methods["baseline"]
            entry: dict[str, Any] = {"groups": int(base.shape[0]), "mean": {}, "gain": {}}
            for method, values in methods.items():
                entry["mean"][method] = np.nanmean(values, axis=0).tolist()
                if method == "baseline" or method in REFERENCES:
                    continue
                entry["gain"][method] = [
                    _paired(values[:, k], base[:, k]).as_dict() for k in range(values.shape[1])
                ]
            if "control" in methods:
                entry["gain"]["APTKT vs control"] = [
                    _paired(methods["APTKT"][:, k], methods["control"][:, k]).as_dict()
                    for k in range(base.shape[1])
                ]
            for ref in REFERENCES:
                if ref in methods:
                    entry["gain"][f"APTKT vs {ref}"] = _paired(
                        methods["APTKT"][:, 0], methods[ref][:, 0]
                    ).as_dict()
            entry_size[choice] = entry
        out[str(size)] = entry_size
    return out


_TITLES = {
    "random": "random priors",
    "nearest": "the most similar priors",
    "farthest": "the least similar priors",
}


def _choice_order(choice: str) -> int:
    return list(_TITLES).index(choice) if choice in _TITLES else 99


AUX = "APTKT+aux"


def _aux_adds_nothing(methods: Mapping[str, np.ndarray]) -> bool:
    """Whether APTKT with the auxiliary features learned exactly as plain APTKT in every group
    and step (their evidence gate stayed shut): a curve that only hides another."""
    return AUX in methods and np.array_equal(methods[AUX], methods["APTKT"], equal_nan=True)


def _panels(c: Curves) -> list[tuple[int, str, Mapping[str, np.ndarray]]]:
    """Each library size and prior choice's curves as shown: APTKT+aux left out where it adds
    nothing (:func:`_aux_adds_nothing`)."""
    return [
        (
            size,
            choice,
            {k: v for k, v in per_choice[choice].items() if k != AUX}
            if _aux_adds_nothing(per_choice[choice])
            else per_choice[choice],
        )
        for size, per_choice in c.items()
        for choice in sorted(per_choice, key=_choice_order)
    ]


def _aux_note(c: Curves) -> list[str]:
    """The report's word on curves left out."""
    same = [
        _label(size, choice, len(c))
        for size, per_choice in c.items()
        for choice, methods in per_choice.items()
        if _aux_adds_nothing(methods)
    ]
    if not same:
        return []
    total = sum(len(per_choice) for per_choice in c.values())
    where = "every library and prior choice" if len(same) == total else ", ".join(same)
    return [
        f"APTKT+aux (APTKT with the auxiliary features) learned exactly as plain APTKT in every "
        f"group and step with {where}: the new labels' evidence never admitted the auxiliary "
        "features. It is left out of the tables and plots there; its curves are in "
        "`results.csv`.",
        "",
    ]


#: Panels side by side in the benchmark's figure: beyond three (about 2,300 px at the saved
#: resolution) a figure is wider than a screen, so further panels go on to the next row.
PLOT_COLUMNS = 3


def plot(c: Curves, chance: float) -> Any:
    """One panel per library size and prior choice, at most :data:`PLOT_COLUMNS` side by side
    (further panels go on to the next row). Top of a panel: each method's mean accuracy with
    its 95 % band (clipped to [0, 1]) and the nearest-neighbour references at step 0; bottom:
    each method's paired gain over the baseline with its band."""
    from matplotlib.ticker import MaxNLocator  # matplotlib is imported when a plot is made

    panels = _panels(c)
    columns = min(len(panels), PLOT_COLUMNS)
    rows = -(-len(panels) // columns)
    fig, axes = figure(2 * rows, columns, figsize=(5.0 * columns, 7.6 * rows), squeeze=False)
    for j in range(len(panels), rows * columns):
        axes[2 * (j // columns), j % columns].set_visible(False)
        axes[2 * (j // columns) + 1, j % columns].set_visible(False)
    for j, (size, choice, methods) in enumerate(panels):
        top, bottom = (
            axes[2 * (j // columns), j % columns],
            axes[2 * (j // columns) + 1, j % columns],
        )
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
        for offset, (ref, marker) in enumerate(zip(REFERENCES, ("D", "s"))):
            if ref not in methods:
                continue
            nn = methods[ref][:, 0]
            _, low, high = mean_band(nn[:, None])
            top.errorbar(
                [0.15 * offset],
                [nn.mean()],
                yerr=[[nn.mean() - low[0]], [high[0] - nn.mean()]],
                fmt=marker,
                color="black" if offset == 0 else "0.45",
                ms=6,
                capsize=3,
                label=_REFERENCE_LABELS[ref],
            )
        top.axhline(chance, color="0.5", ls="--", lw=1, label=f"chance ({chance:.2f})")
        top.set_ylim(0, 1.0)
        title = _TITLES.get(choice, choice)
        if size:
            title = f"{size} {title.replace('the ', '')}"
        top.set_title(f"{title} ({methods['baseline'].shape[0]} groups)")
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


def plot_library(c: Curves) -> Any:
    """Gain against library size (random priors): APTKT and the control over the baseline at
    one observation per object and at the end of the budget, and APTKT over the control, each
    with its 95 % interval — the paper's Fig. 9 question on this data."""
    sizes = [s for s in c if "random" in c[s]]
    fig, axes = figure(1, 2, figsize=(10.0, 4.2), squeeze=False)
    left, right = axes[0]
    last = c[sizes[0]]["random"]["baseline"].shape[1] - 1
    for ax, step, title in ((left, 0, "one observation per object"), (right, last, f"step {last}")):
        # Side by side, so that equal gains stay visible.
        shift = 0.012 * (max(sizes) - min(sizes) or 1)
        for offset, (method, other, look) in enumerate(
            (
                ("APTKT", "baseline", {"color": "C2", "marker": "o", "ls": "-"}),
                ("control", "baseline", {"color": "C1", "marker": "s", "ls": "--"}),
                ("APTKT", "control", {"color": "C3", "marker": "^", "ls": ":"}),
            )
        ):
            est = [
                _paired(c[s]["random"][method][:, step], c[s]["random"][other][:, step])
                for s in sizes
            ]
            mean = np.array([100 * e.mean for e in est])
            err = np.array([[100 * (e.mean - e.low), 100 * (e.high - e.mean)] for e in est]).T
            x = np.asarray(sizes, dtype=float) + (offset - 1) * shift
            ax.errorbar(x, mean, yerr=err, capsize=3, label=f"{method} − {other}", **look)
        ax.axhline(0, color="0.3", lw=1)
        ax.set_xticks(sizes)
        ax.set_xlabel("prior objects in the library (random)")
        ax.set_ylabel("paired gain (pp, 95 % intervals)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    left.legend(loc="best", fontsize="small")
    fig.tight_layout()
    return fig


def _library_table(c: Curves) -> list[str]:
    """The gains against library size (random priors), one row per size."""
    sizes = [s for s in c if "random" in c[s]]
    if len(sizes) < 2:
        return []
    last = c[sizes[0]]["random"]["baseline"].shape[1] - 1
    rows = []
    for s in sizes:
        m = c[s]["random"]
        mean = {k: np.nanmean(v, axis=0) for k, v in m.items()}
        rows.append(
            [
                str(s),
                f"{mean['baseline'][0]:.3f} → {mean['baseline'][last]:.3f}",
                f"{mean['control'][0]:.3f} → {mean['control'][last]:.3f}" if "control" in m else "",
                f"{mean['APTKT'][0]:.3f} → {mean['APTKT'][last]:.3f}",
                ci(_paired(m["APTKT"][:, 0], m["baseline"][:, 0]), cell=True),
                ci(_paired(m["APTKT"][:, last], m["baseline"][:, last]), cell=True),
                ci(_paired(m["APTKT"][:, 0], m["control"][:, 0]), cell=True)
                if "control" in m
                else "",
            ]
        )
    return [
        "## Gain against library size (random priors)",
        "",
        "The same groups — new objects, pool order, first observations — with libraries that "
        "grow: each size's prior objects hold the smaller sizes'. Plot: `library.png` / `.svg`.",
        "",
        markdown_table(
            [
                "priors",
                f"baseline step 0 → {last}",
                f"control step 0 → {last}",
                f"APTKT step 0 → {last}",
                "APTKT − baseline, step 0",
                f"APTKT − baseline, step {last}",
                "APTKT − control, step 0",
            ],
            rows,
        ),
        "",
    ]


def report_markdown(
    c: Curves,
    head: Mapping[str, Any],
    found: Sequence[Check],
    profiles: Sequence[NoiseProfile] = (),
) -> str:
    """report.md: the set-up, each check with its verdict, the gains against library size, the
    curves and the gains of every library and choice, and how the data's noise looks."""
    libraries = head.get("libraries") or [head.get("priors")]
    sizes = ", ".join(str(s) for s in libraries)
    lines = [
        f"# Real-data benchmark: {head['table']}",
        "",
        f"Command: `{head['command']}`  ",
        f"aptkt {head['software_version']}; {head['seconds']:.0f} s on {head['jobs']} process(es); "
        f"{head['date']}.",
        "",
        f"{head['objects']} objects, action(s) {', '.join(head['actions'])}. Each of "
        f"{head['groups']} groups draws {head['new']} new objects and libraries of {sizes} prior "
        "objects three ways (at random, the most and the least similar to the new ones: the "
        "distance between object means in units of the pooled within-object noise); a "
        "group's larger libraries hold its smaller ones. The first half of every object's "
        "trials builds the prior and is the pool learned from; the second half is held out. "
        "Step 0: one observation of each new object per action; then "
        f"{head['budget']} actively chosen ones. Gains are paired by group; intervals are 95 % "
        "Student-t intervals over groups.",
        "",
        "## Checks",
        "",
        checks_table(found, unit=f"{head['groups']} groups"),
        "",
    ]
    lines += _aux_note(c)
    lines += _library_table(c)
    n_sizes = len(c)
    for size, choice, methods in _panels(c):
        n_steps = methods["baseline"].shape[1]
        steps = [s for s in TABLE_STEPS if s < n_steps]
        lines += [f"## {_label(size, choice, n_sizes).capitalize()}", ""]
        rows = []
        for method in (*METHOD_ORDER, *REFERENCES):
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
                    + [
                        ci(_paired(methods[method][:, s], methods["baseline"][:, s]), cell=True)
                        for s in steps
                    ]
                )
        for method, other in (("APTKT", "control"), (AUX, "APTKT")):
            if method in methods and other in methods:
                rows.append(
                    [f"{method} − {other}"]
                    + [
                        ci(_paired(methods[method][:, s], methods[other][:, s]), cell=True)
                        for s in steps
                    ]
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
        "Plots: `benchmark.png` / `.svg` (top: mean accuracy with 95 % bands, the "
        "nearest-neighbour references at step 0; bottom: gains over the baseline). Every "
        "group's curves: `results.csv`; the numbers above: `summary.json`.",
        "",
    ]
    return "\n".join(lines)
