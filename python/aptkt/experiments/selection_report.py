"""The benchmark's report on the active learner: its choice of touches and its own estimate of
its accuracy.

Each learner runs twice on the same groups, pool order and first observations — once choosing
its touches by its selection rule, once picking them uniformly at random — and the two are
compared paired by group: the mean gain over the active steps, the lowest step, and how many
touches the active learner needs to reach the accuracy random picks reach at the end of the
budget (the touches saved). The learner's own estimate of its accuracy
(:class:`~aptkt.learning.estimate.AccuracyEstimate`) is set against the held-out accuracy step
by step (its calibration)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aptkt.experiments.aggregate import Estimate, estimate, mean_band
from aptkt.experiments.benchmark_report import AUX, REFERENCE, ROUNDING, Check
from aptkt.experiments.plots import curve_styles, figure
from aptkt.experiments.report import ci, markdown_table, pp

__all__ = [
    "RANDOM_PICKS",
    "random_arm",
    "ActiveAgainstRandom",
    "compare",
    "touches_to_reach",
    "plot",
    "report_lines",
    "checks",
    "Calibration",
    "calibrate",
]

#: The suffix of a learner's random-picks arm in the results ("APTKT random").
RANDOM_PICKS = " random"
#: The learners whose active choice the benchmark compares with random picks, in order.
LEARNERS = ("baseline", "control", "APTKT", "APTKT+aux")
#: Group resamples behind the interval of the touches needed.
BOOTSTRAP = 2000
#: The prior choice whose libraries the random-picks arms run on.
CHOICE = "random"
#: The reference figures of the active choice: its mean gain over random picks across the
#: active steps, and how far below random it may be at any one step.
ACTIVE_GAIN = 0.01
ACTIVE_DIP = 0.005
#: The learners whose active choice is checked (the others' is reported).
CHECKED = ("baseline", "APTKT")
#: The reference figure of the learner's own estimate: its mean absolute error against the
#: held-out accuracy, both averaged over the groups, over the steps where it exists.
CALIBRATION_ERROR = 0.03


def random_arm(method: str) -> str:
    return f"{method}{RANDOM_PICKS}"


def touches_to_reach(active: np.ndarray, random: np.ndarray) -> float:
    """How many touches after the first round the active learner's mean curve needs to reach
    the random learner's mean accuracy at the end of the budget: the first step at which it
    does, interpolated linearly between steps; NaN if it never does within the budget."""
    a = np.nanmean(active, axis=0)
    target = np.nanmean(random, axis=0)[-1]
    reached = np.flatnonzero(a >= target - 1e-12)
    if reached.size == 0:
        return float("nan")
    k = int(reached[0])
    if k == 0:
        return 0.0
    below, above = a[k - 1], a[k]
    return float(k - 1 + (target - below) / (above - below))


@dataclass(frozen=True)
class ActiveAgainstRandom:
    """One learner's active choice against its random picks, at one library size."""

    learner: str
    library: int
    groups: int
    budget: int
    #: Active − random, each group's mean over steps 1..budget.
    mean_gain: Estimate
    #: The lowest paired mean difference at any step, and that step.
    lowest: float
    lowest_step: int
    #: The largest fall of the active mean curve from one step to the next (0: none).
    largest_fall: float
    #: Touches the active learner needs to reach random's accuracy at the budget, with a
    #: bootstrap 95 % interval over groups (NaN: not within the budget).
    touches: float
    touches_low: float
    touches_high: float

    @property
    def saved(self) -> float:
        """The share of the budget saved (NaN where the active learner never got there)."""
        return 1.0 - self.touches / self.budget if self.budget else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "learner": self.learner,
            "library": self.library,
            "groups": self.groups,
            "budget": self.budget,
            "mean_gain": self.mean_gain.as_dict(),
            "lowest": self.lowest,
            "lowest_step": self.lowest_step,
            "largest_fall": self.largest_fall,
            # NaN and infinities are written as null (aptkt.files.strict_json).
            "touches": self.touches,
            "touches_interval": [self.touches_low, self.touches_high],
            "saved": self.saved,
        }


def compare(c: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]]) -> list[ActiveAgainstRandom]:
    """Every learner with a random-picks arm, at every library size (random priors)."""
    out = []
    for size, per_choice in c.items():
        methods = per_choice.get(CHOICE, {})
        for learner in LEARNERS:
            if learner not in methods or random_arm(learner) not in methods:
                continue
            if learner == AUX and all(
                np.array_equal(methods[arm], methods[other], equal_nan=True)
                for arm, other in ((AUX, "APTKT"), (random_arm(AUX), random_arm("APTKT")))
            ):
                continue  # its evidence gate stayed shut: APTKT's row again
            active, random = methods[learner], methods[random_arm(learner)]
            budget = active.shape[1] - 1
            if budget < 1:
                continue
            diff = active - random
            gain = estimate(
                np.nanmean(diff[:, 1:], axis=1),
                units=list(range(diff.shape[0])),
                unit_name="group",
            )
            per_step = np.nanmean(diff, axis=0)
            low_step = int(np.argmin(per_step[1:])) + 1
            curve = np.nanmean(active, axis=0)
            fall = float(max(0.0, -np.min(np.diff(curve))))
            touches = touches_to_reach(active, random)
            rng = np.random.default_rng(size)
            draws = np.array(
                [
                    touches_to_reach(active[idx], random[idx])
                    for idx in rng.integers(0, active.shape[0], (BOOTSTRAP, active.shape[0]))
                ]
            )
            # A resample in which the active learner never gets there counts as beyond the
            # budget: the interval's upper end is then open.
            draws = np.sort(np.where(np.isfinite(draws), draws, np.inf))
            low, high = draws[int(0.025 * BOOTSTRAP)], draws[int(np.ceil(0.975 * BOOTSTRAP)) - 1]
            out.append(
                ActiveAgainstRandom(
                    learner,
                    int(size),
                    int(active.shape[0]),
                    budget,
                    gain,
                    float(per_step[low_step]),
                    low_step,
                    fall,
                    touches,
                    float(low),
                    float(high),
                )
            )
    return out


def checks(found: list[ActiveAgainstRandom]) -> list[Check]:
    """Reference figures: for the baseline and APTKT at the smallest library, the active
    choice at least :data:`ACTIVE_GAIN` above random picks averaged over the active steps, and
    never more than :data:`ACTIVE_DIP` below at any step."""
    out = []
    smallest = min((r.library for r in found), default=None)
    for r in found:
        if r.learner not in CHECKED or r.library != smallest:
            continue
        out.append(
            Check(
                f"{r.learner}: its own choice at least {100 * ACTIVE_GAIN:.0f} pp above random "
                f"picks over steps 1–{r.budget}, never {100 * ACTIVE_DIP:.1f} pp below at a step",
                f"{ci(r.mean_gain, cell=True)}; lowest {pp(r.lowest)} at step {r.lowest_step}",
                r.mean_gain.mean >= ACTIVE_GAIN - ROUNDING and r.lowest >= -ACTIVE_DIP - ROUNDING,
                REFERENCE,
            )
        )
    return out


@dataclass(frozen=True)
class Calibration:
    """One learner's own estimate of its accuracy against its held-out accuracy, per step
    (random priors, one library size): both averaged over the groups whose estimate exists at
    that step."""

    learner: str
    library: int
    steps: list[int]
    estimated: list[float]
    held_out: list[float]
    #: Groups with an estimate at each step.
    groups: list[int]
    #: Mean absolute error of the averaged estimate over the steps (the calibration), and of
    #: every group's own estimate (each run's).
    error: float
    run_error: float
    #: The accuracy on the pool's touches the learner did not draw, recorded in the same
    #: period as those it learned from (NaN where unknown), and the estimate's mean absolute
    #: error against it: the held-out touches were recorded later, and the difference between
    #: the two accuracies is the data's drift.
    same_period: list[float] = field(default_factory=list)
    same_period_error: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        return {
            "learner": self.learner,
            "library": self.library,
            "steps": self.steps,
            "estimated": self.estimated,
            "held_out": self.held_out,
            "same_period": self.same_period,
            "groups": self.groups,
            "mean_absolute_error": self.error,
            "run_mean_absolute_error": self.run_error,
            "same_period_mean_absolute_error": self.same_period_error,
        }


def calibrate(
    accuracy: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]],
    estimated: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]],
    same_period: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]] | None = None,
) -> list[Calibration]:
    """The calibration of the checked learners' own estimates (their active arms), at every
    library size with random priors (the baseline's once: it uses no library); against the
    held-out accuracy and, where given, against the accuracy on the pool's unused touches of
    the same period."""
    out = []
    for size in accuracy:
        for learner in CHECKED:
            if learner == "baseline" and size != min(accuracy):
                continue
            acc = accuracy[size].get(CHOICE, {}).get(learner)
            est = estimated.get(size, {}).get(CHOICE, {}).get(learner)
            if acc is None or est is None or est.shape != acc.shape:
                continue
            has = np.isfinite(est) & np.isfinite(acc)
            steps = [k for k in range(acc.shape[1]) if has[:, k].any()]
            if not steps:
                continue
            e = [float(est[has[:, k], k].mean()) for k in steps]
            a = [float(acc[has[:, k], k].mean()) for k in steps]
            same = (same_period or {}).get(size, {}).get(CHOICE, {}).get(learner)
            u: list[float] = []
            if same is not None and same.shape == acc.shape:
                u = [
                    float(same[has[:, k], k].mean())
                    if np.isfinite(same[has[:, k], k]).all()
                    else math.nan
                    for k in steps
                ]
            known = [abs(x - y) for x, y in zip(e, u) if np.isfinite(y)]
            out.append(
                Calibration(
                    learner,
                    int(size),
                    steps,
                    e,
                    a,
                    [int(has[:, k].sum()) for k in steps],
                    float(np.mean(np.abs(np.subtract(e, a)))),
                    float(np.mean(np.abs(est[has] - acc[has]))),
                    u,
                    float(np.mean(known)) if known else math.nan,
                )
            )
    return out


def calibration_checks(found: list[Calibration]) -> list[Check]:
    """Reference figure: APTKT's own estimate, at the smallest library, within
    :data:`CALIBRATION_ERROR` of its held-out accuracy (both averaged over the groups)."""
    smallest = min((c.library for c in found), default=None)
    return [
        Check(
            f"APTKT's own estimate of its accuracy within {100 * CALIBRATION_ERROR:.0f} pp of "
            f"its held-out accuracy (means over groups; mean absolute error over steps "
            f"{c.steps[0]}–{c.steps[-1]})",
            f"{100 * c.error:.1f} pp (each run's own: {100 * c.run_error:.1f} pp)",
            c.error <= CALIBRATION_ERROR + ROUNDING,
            REFERENCE,
        )
        for c in found
        if c.learner == "APTKT" and c.library == smallest
    ]


def calibration_lines(found: list[Calibration], libraries: int) -> list[str]:
    """report.md's section on the learners' own estimates."""
    if not found:
        return []
    shown = [k for k in (1, 2, 3, 5, 10, 20, 40) if k in found[0].steps]
    with_same = any(np.isfinite(c.same_period_error) for c in found)
    rows = []
    for c in found:
        same = dict(zip(c.steps, c.same_period))
        at = {
            k: f"{e:.3f} / {h:.3f}"
            + (f" / {same[k]:.3f}" if np.isfinite(same.get(k, math.nan)) else "")
            for k, e, h in zip(c.steps, c.estimated, c.held_out)
        }
        rows.append(
            [c.learner + (f" ({c.library} priors)" if libraries > 1 else "")]
            + [at.get(k, "—") for k in shown]
            + [f"{100 * c.error:.1f} pp", f"{100 * c.run_error:.1f} pp"]
            + ([_pp_or_dash(c.same_period_error)] if with_same else [])
        )
    return [
        "## The learner's own estimate of its accuracy",
        "",
        "Every touch after the first round is judged before it is learned; each judgement is "
        "carried to the pair's current number of touches by the 1/n learning curve the "
        "selection rule assumes (`aptkt.learning.estimate`). `--target-accuracy` stops on "
        "this estimate. Estimated / held-out accuracy"
        + (" / accuracy on the pool's touches not drawn" if with_same else "")
        + ", each averaged over the groups whose estimate exists (random priors); the mean "
        "absolute error of those averages over the steps, and of each run's own estimate"
        + (
            ". The held-out touches are each object's later trials; the pool's are of the "
            "same period as the touches learned. The estimate can only know the touches it "
            "judged: where the two accuracies differ, the data drifted between the periods "
            "(the sensor, the objects, the room), and the estimate is off by as much on "
            "touches recorded later."
            if with_same
            else "."
        ),
        "",
        markdown_table(
            ["learner", *(f"step {k}" for k in shown), "error of the mean", "each run's error"]
            + (["error against the same period"] if with_same else []),
            rows,
        ),
        "",
    ]


def _pp_or_dash(x: float) -> str:
    return f"{100 * x:.1f} pp" if np.isfinite(x) else "—"


def _touches_cell(r: ActiveAgainstRandom) -> str:
    if not np.isfinite(r.touches):
        return f"not within {r.budget}"
    high = "beyond the budget" if not np.isfinite(r.touches_high) else f"{r.touches_high:.1f}"
    return f"{r.touches:.1f} [{r.touches_low:.1f}, {high}]"


def report_lines(found: list[ActiveAgainstRandom], libraries: int) -> list[str]:
    """report.md's section: the table of every learner's active choice against random."""
    if not found:
        return []
    rows = [
        [
            r.learner + (f" ({r.library} priors)" if libraries > 1 else ""),
            ci(r.mean_gain, cell=True),
            f"{pp(r.lowest)} (step {r.lowest_step})",
            f"{100 * r.largest_fall:.2f} pp",
            _touches_cell(r),
            f"{100 * r.saved:.0f} %" if np.isfinite(r.saved) else "—",
        ]
        for r in found
    ]
    budget = found[0].budget
    return [
        "## Active choice against random picks",
        "",
        "Each learner also ran with uniformly random picks on the same groups, pool order and "
        f"first observations (random priors). Gain: active − random, each group's mean over "
        f"steps 1–{budget}, with its 95 % interval; lowest: the lowest paired mean difference "
        "at any step; fall: the largest drop of the active mean curve from one step to the "
        f"next; touches: how many touches after step 0 the active learner needs to reach "
        f"random's mean accuracy at step {budget} (interpolated; 95 % bootstrap interval over "
        "groups); saved: the share of the budget it saves. APTKT+aux is left out where it "
        "learned exactly as APTKT in both arms.",
        "",
        markdown_table(
            ["learner", "gain", "lowest", "fall", "touches to random's end", "saved"], rows
        ),
        "",
        "Plot: `selection.png` / `.svg`.",
        "",
    ]


def plot(c: Mapping[int, Mapping[str, Mapping[str, np.ndarray]]], size: int) -> Any:
    """Active (solid) against random picks (dashed) for the baseline and APTKT at one library
    size (random priors): mean accuracy with 95 % bands on top, the paired difference below."""
    from matplotlib.ticker import MaxNLocator  # matplotlib is imported when a plot is made

    methods = c[size][CHOICE]
    # The learners the checks judge: the others' curves run on top of APTKT's and hide it
    # (the table lists them).
    learners = [m for m in CHECKED if m in methods and random_arm(m) in methods]
    fig, (top, bottom) = figure(2, 1, figsize=(6.4, 7.6), sharex=True)
    steps = np.arange(methods[learners[0]].shape[1])
    styles = curve_styles(learners, len(steps))
    for learner, look in styles.items():
        colour = {k: v for k, v in look.items() if k != "ls"}
        for arm, dash in ((learner, "-"), (random_arm(learner), "--")):
            mean, low, high = mean_band(methods[arm])
            top.plot(steps, mean, ls=dash, label=arm, **colour)
            band = (np.clip(low, 0, 1), np.clip(high, 0, 1))
            top.fill_between(steps, *band, alpha=0.08, **_fill(colour))
        d_mean, d_low, d_high = mean_band(methods[learner] - methods[random_arm(learner)])
        bottom.plot(steps, 100 * d_mean, ls="-", label=f"{learner}: active − random", **colour)
        bottom.fill_between(steps, 100 * d_low, 100 * d_high, alpha=0.12, **_fill(colour))
    bottom.axhline(0.0, color="grey", linewidth=0.8)
    bottom.xaxis.set_major_locator(MaxNLocator(integer=True))
    top.set_ylabel("mean accuracy")
    top.set_title(f"Active choice (solid) against random picks (dashed), {size} random priors")
    top.legend(fontsize="small")
    bottom.set_xlabel("touches after the first round")
    bottom.set_ylabel("active − random (pp)")
    bottom.legend(fontsize="small")
    return fig


def _fill(look: Mapping[str, Any]) -> dict[str, Any]:
    return {"color": look["color"]} if "color" in look else {}
