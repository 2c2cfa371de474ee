"""The docs' real-data figures are benchmark runs' own.

The BioTac set has no licence, so neither it nor anything derived from it is committed, its
benchmark results included: the figures cannot be checked against a file in the repository as
the simulated world's are (tests/docs/test_figures.py). Point ``APTKT_BIOTAC_RUNS`` at a
directory holding the outputs of the docs' own commands (docs/real-data.md, "Checking the
figures": ``biotac-benchmark``, ``biotac-paper``, ``sweep``, ``lifelong``, ``recognition``,
``stream`` and ``biotac-noise.json``), and this renders every real-data table row and figure
of the README, docs/results.md, docs/real-data.md, docs/method.md, docs/recognition.md and
docs/simulation.md from those runs and finds it in the page. Without the variable the checks
are skipped, saying why; a run the directory lacks skips its own checks. Times and memory are
the machine's and are not compared. Re-measure, then run it, whenever the learner changes.

The renderers are checked on made-up runs below, so that the checks cannot pass vacuously.
"""

from __future__ import annotations

import csv
import json
import os
import re
import statistics
from collections import defaultdict
from pathlib import Path

import pytest

from aptkt.experiments.aggregate import Estimate, estimate
from aptkt.experiments.report import ci, pp, span

ROOT = Path(__file__).resolve().parents[2]
RUNS = os.environ.get("APTKT_BIOTAC_RUNS")
#: The docs' names for the benchmark's prior choices.
CHOICES = {
    "random": "random priors",
    "nearest": "the most similar priors",
    "farthest": "the least similar priors",
}
#: The steps the docs' accuracy tables show.
STEPS = (0, 1, 2, 3, 5, 10, 20)

# ----------------------------------------------------------------------------- rendering


def cell(e: dict | Estimate) -> str:
    return ci(e if isinstance(e, Estimate) else Estimate(**_fields(e)), cell=True)


def _fields(e: dict) -> dict:
    return {k: e[k] for k in ("mean", "low", "high", "n", "unit")}


def accuracy_row(summary: dict, label: str, choice: str, method: str, library: str = "3") -> str:
    """A row of mean accuracy at :data:`STEPS` (a reference measured at step 0 only leaves
    the later cells empty)."""
    curve = summary["results"][library][choice]["mean"][method]
    cells = [f"{curve[s]:.3f}" if s < len(curve) else "" for s in STEPS]
    return f"| {label} | {' | '.join(cells)} |"


def readme_rows(summary: dict) -> list[str]:
    """The README's table rows at one observation per new material."""
    rows = []
    for choice, label in CHOICES.items():
        result = summary["results"]["3"][choice]
        baseline, aptkt = result["mean"]["baseline"][0], result["mean"]["APTKT"][0]
        gain = cell(result["gain"]["APTKT"][0])
        rows.append(f"| {label} | {baseline:.3f} | {aptkt:.3f} | {gain} |")
    return rows


def gains_at(summary: dict, step: int, library: str = "3") -> str:
    """``+1.9, +2.4 and +0.4 pp``: APTKT − baseline at ``step``, random, nearest, farthest."""
    g = [summary["results"][library][c]["gain"]["APTKT"][step]["mean"] for c in CHOICES]
    return f"{100 * g[0]:+.1f}, {100 * g[1]:+.1f} and {100 * g[2]:+.1f} pp"


def checks(summary: dict) -> str:
    """How many checks hold and reference figures are reached, in the words the command
    prints last (``6 of 6 checks hold; 7 of 7 reference figures reached``)."""
    invariants = [c for c in summary["checks"] if c["kind"] == "invariant"]
    references = [c for c in summary["checks"] if c["kind"] == "reference"]
    held = sum(c["holds"] for c in invariants)
    reached = sum(c["holds"] for c in references)
    return (
        f"{held} of {len(invariants)} checks hold; "
        f"{reached} of {len(references)} reference figures reached"
    )


def measured(summary: dict, claim_starts: str) -> str:
    """The report's own figure for the check whose claim starts so."""
    (found,) = [c for c in summary["checks"] if c["claim"].startswith(claim_starts)]
    return found["measured"]


def largest_fall(summary: dict) -> str:
    return measured(summary, "no method unlearns").split(" (")[0]


def active_row(summary: dict, learner: str) -> str:
    """docs/results.md's row of a learner's own choice against random picks."""
    (a,) = [x for x in summary["active_against_random"] if x["learner"] == learner]
    lo, hi = a["touches_interval"]
    return (
        f"| {learner} | {cell(a['mean_gain'])} | {pp(a['lowest'])} (step {a['lowest_step']}) "
        f"| {a['touches']:.1f} [{lo:.1f}, {hi:.1f}] | {100 * a['saved']:.0f} % |"
    )


def rule_row(summary: dict, learner: str, rule: str) -> str:
    """docs/method.md's row of a learner's own choice by ``rule`` against random picks."""
    (a,) = [x for x in summary["active_against_random"] if x["learner"] == learner]
    return (
        f"| {learner} | {rule} | {cell(a['mean_gain'])} | {pp(a['lowest'])} "
        f"(step {a['lowest_step']}) | {100 * a['largest_fall']:.2f} pp |"
    )


def own_estimate(summary: dict) -> list[str]:
    """APTKT's and the baseline's own estimate against the held-out and the same-period
    accuracy (mean absolute error over the steps)."""
    e = {x["learner"]: x for x in summary["own_estimate"]}
    a, b = e["APTKT"], e["baseline"]
    return [
        f"{100 * a['mean_absolute_error']:.1f} pp (APTKT) and "
        f"{100 * b['mean_absolute_error']:.1f} pp (baseline) of the held-out accuracy",
        f"{100 * a['same_period_mean_absolute_error']:.1f} and "
        f"{100 * b['same_period_mean_absolute_error']:.1f} pp of the accuracy on the pool's",
    ]


def sweep_row(summary: dict, library: str) -> str:
    """docs/results.md's row of a library size (random priors)."""
    r = summary["results"][library]["random"]
    m, vs_control = r["mean"], r["gain"]["APTKT vs control"]
    worst = min(range(len(vs_control)), key=lambda s: vs_control[s]["mean"])
    spans = " | ".join(f"{m[k][0]:.3f} → {m[k][20]:.3f}" for k in ("baseline", "control", "APTKT"))
    gains = f"{cell(r['gain']['APTKT'][0])} | {cell(r['gain']['APTKT'][20])}"
    return f"| {library} | {spans} | {gains} | {pp(vs_control[worst]['mean'])} (step {worst}) |"


def sweep_gains(summary: dict, step: int) -> str:
    """``+11.1, +10.6, +10.5 and +11.8 pp``: APTKT − baseline at ``step`` by library size."""
    g = [
        f"{100 * summary['results'][k]['random']['gain']['APTKT'][step]['mean']:+.1f}"
        for k in map(str, summary["libraries"])
    ]
    return f"{', '.join(g[:-1])} and {g[-1]} pp"


def sweep_nearest(summary: dict) -> str:
    """The largest library's APTKT against both 1-NN rules at one shot."""
    k = str(summary["libraries"][-1])
    m = summary["results"][k]["random"]["mean"]
    return (
        f"with {k} priors: {m['APTKT'][0]:.3f} against {m['1-NN'][0]:.3f} in its own metric "
        f"and {m['1-NN shrunk'][0]:.3f} in the priors' shrunk covariance"
    )


def sweep_lowest(summary: dict) -> str:
    """Over every size, APTKT's lowest mean gain over the baseline and its worst step
    against the control."""
    lowest = min(
        g["mean"]
        for k in map(str, summary["libraries"])
        for g in summary["results"][k]["random"]["gain"]["APTKT"]
    )
    worst = min(
        g["mean"]
        for k in map(str, summary["libraries"])
        for g in summary["results"][k]["random"]["gain"]["APTKT vs control"]
    )
    return f"(lowest {pp(lowest)}), never more than {-100 * worst:.1f} pp below the control"


def paired_over_steps(
    a: Path, b: Path, method: str, choice: str, steps: range = range(1, 21)
) -> Estimate:
    """``a`` − ``b`` (two runs' ``results.csv`` on the same groups), each group's mean over
    ``steps``, with its interval over groups."""
    acc: dict[Path, dict[str, list[float]]] = {}
    for path in (a, b):
        per_group: dict[str, list[float]] = defaultdict(list)
        with path.open(newline="") as f:
            for row in csv.DictReader(f):
                if (
                    row["method"] == method
                    and row["priors"] == choice
                    and int(row["step"]) in steps
                ):
                    per_group[row["group"]].append(float(row["accuracy"]))
        acc[path] = per_group
    groups = sorted(acc[a], key=int)
    assert groups == sorted(acc[b], key=int), "the two runs are not on the same groups"
    diffs = [sum(acc[a][g]) / len(acc[a][g]) - sum(acc[b][g]) / len(acc[b][g]) for g in groups]
    return estimate(diffs)


def no_fall_above(summary: dict) -> str:
    """``falls by more than 0.1 pp``: the report's largest fall of a mean curve."""
    (fall,) = re.findall(r"largest fall ([0-9.]+) pp", measured(summary, "no method unlearns"))
    return f"falls by more than {fall} pp"


def active_gist(summary: dict) -> str:
    """The README's sentence on APTKT's own choice against random picks."""
    (a,) = [x for x in summary["active_against_random"] if x["learner"] == "APTKT"]
    return (
        f"APTKT gains {cell(a['mean_gain'])} on average over the 20 steps and reaches random "
        f"picks' final accuracy after {a['touches']:.1f} touches"
    )


def noise_profile(summary: dict) -> dict[str, dict[str, float]]:
    """Each figure of the report's noise profile by modality."""
    figures = ("separation", "drift", "heterogeneity")
    return {f: {r["modality"]: r[f] for r in summary["noise_profile"]} for f in figures}


def noise_spans_row(summary: dict) -> str:
    """docs/real-data.md's row of the set's noise profile: each figure's range."""
    spans = [span(list(v.values()), "{:.1f}", "") for v in noise_profile(summary).values()]
    return f"| BioTac, 4 modalities | {' | '.join(spans)} |"


def noise_medians_row(summary: dict) -> str:
    """docs/simulation.md's row of the table in the noise fit: each figure's median."""
    medians = [f"{statistics.median(v.values()):.2f}" for v in noise_profile(summary).values()]
    return f"| the table |  |  |  | {' | '.join(medians)} |"


def noise_by_modality(summary: dict) -> list[str]:
    """docs/simulation.md's BioTac figures beside the simulated world's, by modality."""
    n = noise_profile(summary)
    sep = n["separation"]
    return [
        f"(the BioTac pressure {sep['pressure']:.1f})",
        f"(temperature {sep['temperature']:.1f})",
        f"(vibration {sep['vibration']:.1f})",
        f"against {n['drift']['vibration']:.1f})",
    ]


def lifelong_row(summary: dict, batch: str) -> str:
    """docs/results.md's row of a lifelong batch."""
    r = summary["results"][batch]
    library, ncm = r["mean"]["library"][0], r["mean"]["NCM"][0]
    return (
        f"| {batch} | {r['learned_with']:.0f} | {cell(r['gain_one_shot'])} "
        f"| {cell(r['gain_last_step'])} | {library:.3f} ({ncm:.3f}), "
        f"{r['library_size']:.0f} materials |"
    )


def lifelong_gist(summary: dict) -> list[str]:
    """docs/method.md's figures of the lifelong benchmark."""
    batches = sorted(summary["results"], key=int)
    g = [f"{100 * summary['results'][b]['gain_one_shot']['mean']:+.1f}" for b in batches]
    last = summary["results"][batches[-1]]["mean"]
    return [
        f"gains {', '.join(g[:-1])} and {g[-1]} pp at one observation",
        f"with {last['library'][0]:.3f} (the nearest class mean in its metric, on the same "
        f"observations: {last['NCM'][0]:.3f})",
    ]


def recognition_rows(summary: dict, draws: Path) -> list[str]:
    """docs/recognition.md's table and docs/results.md's sentence."""
    r = summary["results"]

    def three(e: dict) -> str:
        return f"{e['mean']:.3f}** [{e['low']:.3f}, {e['high']:.3f}]"

    def percent(e: dict, digits: int) -> str:
        m, lo, hi = (f"{100 * e[k]:.{digits}f}" for k in ("mean", "low", "high"))
        return f"{m} % [{lo}, {hi}]"

    with draws.open(newline="") as f:
        lowest = min(float(row["auroc"]) for row in csv.DictReader(f))
    ncm = three(r["ncm"]).replace("**", "")
    return [
        f"| accuracy on the library's materials | **{three(r['accuracy'])} (nearest class mean "
        f"in the library's metric: {ncm}) |",
        f"| novelty AUROC | **{three(r['auroc'])} (lowest draw {lowest:.3f}) |",
        f"| touches of known materials flagged as new (asked: 5 %) | "
        f"{percent(r['false_alarms'], 1)} |",
        f"| touches of unknown materials flagged as new | {percent(r['detected'], 0)} |",
    ]


def recognition_gist(summary: dict) -> list[str]:
    r = summary["results"]
    return [
        f"with {r['accuracy']['mean']:.3f} (the nearest class mean: {r['ncm']['mean']:.3f})",
        f"novelty AUROC of {r['auroc']['mean']:.3f} ({r['auroc']['n']} draws)",
    ]


def noise_fit_rows(fit: dict) -> list[str]:
    """docs/simulation.md's table of the noise fit's probes (``fit-noise --json``)."""

    def level(v: float) -> str:
        return str(int(v)) if v == int(v) else f"{v:.3f}"

    rows = []
    for i, probe in enumerate(fit["probes"], 1):
        lv = probe["level"]
        cells = [level(lv[k]) for k in ("trial", "drift", "objects")]
        cells += [f"{probe[k]:.2f}" for k in ("separation", "drift", "heterogeneity")]
        if lv == fit["level"]:
            cells = [f"**{c}**" for c in [f"{i}: the fit", *cells]]
        else:
            cells = [f"{i} (physical defaults)" if i == 1 else str(i), *cells]
        rows.append(f"| {' | '.join(cells)} |")
    return rows


def stream_rows(summary: dict, shown: tuple[int, ...] = (5, 80, 480, 980)) -> list[str]:
    """docs/results.md's rows of the synthetic stream at the batches learned with ``shown``
    objects, up to the accuracies (the CPU seconds and memory after them are the machine's)."""
    rows = []
    for r in summary["results"].values():
        if int(r["learned_with"]) in shown:
            library, ncm = r["mean"]["library"][0], r["mean"]["NCM"][0]
            rows.append(
                f"| {r['learned_with']:.0f} | {cell(r['gain_one_shot'])} "
                f"| {cell(r['gain_last_step'])} | {library:.3f} / {ncm:.3f} |"
            )
    assert len(rows) == len(shown), "the run has no batch learned with some of them"
    return rows


def differences(summary: dict) -> list[str]:
    """The growth checks' paired differences, as the report measured them."""
    found = [re.search(r"\(difference (.+)\)$", c["measured"]) for c in summary["checks"]]
    return [f.group(1) for f in found if f is not None]


# ----------------------------------------------------------------------------- the checks


def page(name: str) -> str:
    """A page's text with its minus signs as Python writes them, whitespace as single spaces
    (a figure may be wrapped over two lines)."""
    text = (ROOT / name).read_text(encoding="utf-8").replace("−", "-")
    return " ".join(text.lower().split())


def run_file(name: str) -> Path:
    """A file or directory of the runs, or skip saying why it is not there."""
    if RUNS is None:
        pytest.skip(
            "the BioTac benchmark's results may not be committed: set APTKT_BIOTAC_RUNS to a "
            "directory of the runs docs/real-data.md names to check the docs against them"
        )
    path = Path(RUNS) / name
    if not path.exists():
        pytest.skip(f"{path} is missing")
    return path


def run(name: str) -> Path:
    """A benchmark's output directory."""
    d = run_file(name)
    if not (d / "summary.json").is_file():
        pytest.skip(f"{d} holds no benchmark run ({d / 'summary.json'} is missing)")
    return d


def summary_of(name: str) -> dict:
    return json.loads((run(name) / "summary.json").read_text())


def assert_quoted(name: str, figures: list[str]) -> None:
    text = page(name)
    missing = [f for f in figures if " ".join(f.lower().split()) not in text]
    assert not missing, f"{name} lacks the run's:\n" + "\n".join(missing)


def test_the_readme_quotes_the_default_run():
    s = summary_of("biotac-benchmark")
    figures = [f"at step 20 by {gains_at(s, 20)}", no_fall_above(s), active_gist(s), checks(s)]
    assert_quoted("README.md", [*readme_rows(s), *figures])
    # "APTKT stays above the baseline at every one of the 20 later steps with every choice"
    for choice in CHOICES:
        assert min(g["mean"] for g in s["results"]["3"][choice]["gain"]["APTKT"]) > 0, choice


def quotes_three_ways(summary: dict, rows: list[tuple[str, str, str]]) -> None:
    """docs/real-data.md's section on a run with priors chosen three ways: its accuracy
    ``rows`` (label, prior choice, method), the gains at steps 0 and 20 and the checks."""
    table = [accuracy_row(summary, *row) for row in rows]
    gains = [f"({gains_at(summary, 0)}", f"at step 20 {gains_at(summary, 20)}"]
    assert_quoted("docs/real-data.md", [*table, *gains, checks(summary)])


def test_real_data_md_quotes_the_default_run():
    s = summary_of("biotac-benchmark")
    quotes_three_ways(
        s,
        [
            ("baseline", "random", "baseline"),
            ("baseline, random picks", "random", "baseline random"),
            ("APTKT, random priors", "random", "APTKT"),
            ("APTKT, random priors, random picks", "random", "APTKT random"),
            ("APTKT, most similar priors", "nearest", "APTKT"),
            ("APTKT, least similar priors", "farthest", "APTKT"),
        ],
    )
    assert_quoted("docs/real-data.md", [noise_spans_row(s)])
    assert_quoted("docs/simulation.md", [noise_medians_row(s), *noise_by_modality(s)])
    # "APTKT with auxiliary features learned exactly as APTKT in every group"
    for choice in CHOICES:
        mean = s["results"]["3"][choice]["mean"]
        assert mean["APTKT+aux"] == mean["APTKT"], choice


def test_real_data_md_quotes_the_paper_selection_run():
    s = summary_of("biotac-paper")
    quotes_three_ways(
        s,
        [
            ("baseline", "random", "baseline"),
            ("APTKT, random priors", "random", "APTKT"),
            ("APTKT, most similar priors", "nearest", "APTKT"),
            ("APTKT, least similar priors", "farthest", "APTKT"),
            ("1-NN in the prior's metric (random priors)", "random", "1-NN"),
        ],
    )
    (estimate_check,) = [c for c in s["checks"] if c["claim"].startswith("APTKT's own estimate")]
    assert not estimate_check["holds"], "the page says this reference figure is not reached"
    own = estimate_check["measured"].split(" (")[0]
    assert_quoted("docs/real-data.md", [f"own estimate of its accuracy is {own} from"])
    mean = s["results"]["3"]["random"]["mean"]
    ends = f"the baseline ends at {mean['baseline'][20]:.3f} and APTKT at {mean['APTKT'][20]:.3f}"
    assert_quoted("docs/results.md", [ends])


def test_the_rules_compared_are_the_runs():
    """The two rules for the next touch, each against random picks (docs/method.md,
    docs/results.md) and against each other on the same groups (docs/real-data.md)."""
    default, paper = run("biotac-benchmark"), run("biotac-paper")
    d, p = summary_of("biotac-benchmark"), summary_of("biotac-paper")
    assert_quoted(
        "docs/method.md",
        [
            rule_row(d, "baseline", "error reduction"),
            rule_row(p, "baseline", "AT-LPP"),
            rule_row(d, "APTKT", "error reduction"),
            rule_row(p, "APTKT", "AT-LPP"),
            *own_estimate(d)[:1],
        ],
    )
    assert_quoted(
        "docs/results.md",
        [active_row(d, "baseline"), active_row(d, "APTKT"), *own_estimate(d)],
    )
    against = [
        f"{who} {cell(paired_over_steps(default / 'results.csv', paper / 'results.csv', m, c))}"
        for who, m, c in [
            ("baseline", "baseline", "random"),
            ("APTKT with random priors", "APTKT", "random"),
            ("with the most similar", "APTKT", "nearest"),
            ("with the least similar", "APTKT", "farthest"),
        ]
    ]
    assert_quoted("docs/real-data.md", against)


def test_the_library_sweep_is_the_run():
    s = summary_of("sweep")
    rows = [sweep_row(s, str(k)) for k in s["libraries"]]
    assert_quoted(
        "docs/results.md",
        [*rows, sweep_nearest(s), sweep_lowest(s), checks(s), largest_fall(s)],
    )
    assert_quoted(
        "docs/method.md",
        [f"is {sweep_gains(s, 0)} with", f"at step 20 {sweep_gains(s, 20)}"],
    )


def test_the_noise_fit_is_the_run():
    fit = json.loads(run_file("biotac-noise.json").read_text())
    assert_quoted("docs/simulation.md", noise_fit_rows(fit))


def test_the_lifelong_benchmark_is_the_run():
    s = summary_of("lifelong")
    rows = [lifelong_row(s, b) for b in sorted(s["results"], key=int)]
    assert_quoted("docs/results.md", rows)
    assert_quoted("docs/method.md", lifelong_gist(s))


def test_the_stream_of_a_thousand_objects_is_the_run():
    s = summary_of("stream")
    assert_quoted("docs/results.md", [*stream_rows(s), *differences(s), checks(s)])


def test_the_recognition_benchmark_is_the_run():
    s = summary_of("recognition")
    assert_quoted("docs/recognition.md", recognition_rows(s, run("recognition") / "results.csv"))
    assert_quoted("docs/results.md", recognition_gist(s))


# ------------------------------------------------------------- the renderers on made-up runs


def made_up_run() -> dict:
    """A summary.json of the benchmark's shape with known figures."""

    def est(mean: float) -> dict:
        return {"mean": mean, "low": mean - 0.023, "high": mean + 0.023, "n": 60, "unit": "groups"}

    def result(offset: float) -> dict:
        curve = [0.7657 + 0.01 * s for s in range(21)]
        return {
            "mean": {
                "baseline": curve,
                "control": [x + 0.1 for x in curve],
                "APTKT": [x + offset for x in curve],
                "1-NN": [0.8526],
                "1-NN shrunk": [0.8504],
            },
            "gain": {
                "APTKT": [est(offset)] * 21,
                "APTKT vs control": [est(0.001 * (s - 3) ** 2 - 0.002) for s in range(21)],
            },
        }

    return {
        "libraries": [3, 15],
        "results": {
            "3": {c: result(0.111 - 0.01 * i) for i, c in enumerate(CHOICES)},
            "15": {"random": result(0.118)},
        },
        "checks": [
            {"kind": "invariant", "holds": True, "claim": "a", "measured": "x"},
            {"kind": "invariant", "holds": False, "claim": "b", "measured": "y"},
            {"kind": "reference", "holds": True, "claim": "c", "measured": "z"},
            {
                "kind": "invariant",
                "holds": True,
                "claim": "no method unlearns: no mean curve falls",
                "measured": "largest fall 0.1 pp (APTKT+aux, random priors, step 15)",
            },
        ],
        "active_against_random": [
            {
                "learner": "APTKT",
                "mean_gain": est(0.023),
                "lowest": -0.002,
                "lowest_step": 1,
                "largest_fall": 0.0009,
                "touches": 7.4545,
                "touches_interval": [4.73, 12.49],
                "saved": 0.6272,
            }
        ],
        "own_estimate": [
            {
                "learner": "APTKT",
                "mean_absolute_error": 0.0297,
                "same_period_mean_absolute_error": 0.0061,
            },
            {
                "learner": "baseline",
                "mean_absolute_error": 0.0317,
                "same_period_mean_absolute_error": 0.0084,
            },
        ],
    }


def test_the_renderers_write_as_the_docs_do():
    s = made_up_run()
    assert readme_rows(s)[0] == "| random priors | 0.766 | 0.877 | +11.1 pp [+8.8, +13.4] |"
    assert readme_rows(s)[1].startswith("| the most similar priors | 0.766 | 0.867 | +10.1 pp")
    assert gains_at(s, 20) == "+11.1, +10.1 and +9.1 pp"
    assert accuracy_row(s, "b", "random", "baseline") == (
        "| b | 0.766 | 0.776 | 0.786 | 0.796 | 0.816 | 0.866 | 0.966 |"
    )
    assert accuracy_row(s, "1-NN", "random", "1-NN") == "| 1-NN | 0.853 |  |  |  |  |  |  |"
    assert checks(s) == "2 of 3 checks hold; 1 of 1 reference figures reached"
    assert largest_fall(s) == "largest fall 0.1 pp"
    assert active_row(s, "APTKT") == (
        "| APTKT | +2.3 pp [+0.0, +4.6] | -0.2 pp (step 1) | 7.5 [4.7, 12.5] | 63 % |"
    )
    assert rule_row(s, "APTKT", "AT-LPP") == (
        "| APTKT | AT-LPP | +2.3 pp [+0.0, +4.6] | -0.2 pp (step 1) | 0.09 pp |"
    )
    assert own_estimate(s) == [
        "3.0 pp (APTKT) and 3.2 pp (baseline) of the held-out accuracy",
        "0.6 and 0.8 pp of the accuracy on the pool's",
    ]
    # (APTKT vs control is lowest, −0.2 pp, at step 3.)
    assert sweep_row(s, "15") == (
        "| 15 | 0.766 → 0.966 | 0.866 → 1.066 | 0.884 → 1.084 | +11.8 pp [+9.5, +14.1] "
        "| +11.8 pp [+9.5, +14.1] | -0.2 pp (step 3) |"
    )
    assert sweep_gains(s, 0) == "+11.1 and +11.8 pp"
    assert sweep_nearest(s) == (
        "with 15 priors: 0.884 against 0.853 in its own metric and 0.850 in the priors' shrunk "
        "covariance"
    )
    assert sweep_lowest(s) == "(lowest +11.1 pp), never more than 0.2 pp below the control"


def test_the_noise_fit_renders_as_the_page_does():
    def probe(trial: float, drift: float, objects: float, figures: tuple) -> dict:
        level = {"trial": trial, "drift": drift, "objects": objects}
        return {"level": level, **dict(zip(("separation", "drift", "heterogeneity"), figures))}

    fit = {
        "level": {"trial": 1.0306, "drift": 1.5041, "objects": 0.5131},
        "probes": [
            probe(1.0, 1.0, 0.0, (3.02, 1.849, 3.27)),
            probe(1.0306, 1.5041, 0.5131, (2.46, 2.08, 4.371)),
        ],
    }
    assert noise_fit_rows(fit) == [
        "| 1 (physical defaults) | 1 | 1 | 0 | 3.02 | 1.85 | 3.27 |",
        "| **2: the fit** | **1.031** | **1.504** | **0.513** | **2.46** | **2.08** | **4.37** |",
    ]


def test_the_lifelong_renderers_write_as_the_page_does():
    def est(mean: float) -> dict:
        return {"mean": mean, "low": mean - 0.05, "high": mean + 0.05, "n": 8, "unit": "orders"}

    def batch(learned_with: int, one_shot: float) -> dict:
        return {
            "learned_with": float(learned_with),
            "library_size": float(learned_with + 5),
            "gain_one_shot": est(one_shot),
            "gain_last_step": est(0.06),
            "mean": {"library": [0.9861], "NCM": [0.97]},
        }

    s = {
        "results": {"1": batch(5, 0.142), "2": batch(10, 0.15), "3": batch(80, 0.146)},
        "checks": [{"measured": "+27.8 pp against +14.2 pp (difference +13.6 pp [+7.5, +19.7])"}],
    }
    assert stream_rows(s, shown=(5, 80)) == [
        "| 5 | +14.2 pp [+9.2, +19.2] | +6.0 pp [+1.0, +11.0] | 0.986 / 0.970 |",
        "| 80 | +14.6 pp [+9.6, +19.6] | +6.0 pp [+1.0, +11.0] | 0.986 / 0.970 |",
    ]
    assert differences(s) == ["+13.6 pp [+7.5, +19.7]"]
    assert lifelong_row(s, "2") == (
        "| 2 | 10 | +15.0 pp [+10.0, +20.0] | +6.0 pp [+1.0, +11.0] | 0.986 (0.970), 15 materials |"
    )
    with pytest.raises(AssertionError, match="no batch"):
        stream_rows(s, shown=(5, 480))


def test_paired_differences_pair_by_group(tmp_path: Path):
    """Group by group, the mean over the steps of one run minus the other's, then a t interval
    over groups (checked against the closed form for three groups)."""
    header = "group,library,priors,new_objects,prior_objects,method,step,accuracy\n"
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    rows_a, rows_b = [header], [header]
    for g, shift in enumerate([0.01, 0.02, 0.06]):
        for step in range(21):
            acc = 0.8 + 0.005 * step
            rows_a.append(f"{g},3,random,x,y,APTKT,{step},{acc + shift}\n")
            rows_b.append(f"{g},3,random,x,y,APTKT,{step},{acc}\n")
            rows_b.append(f"{g},3,random,x,y,baseline,{step},0.1\n")
    a.write_text("".join(rows_a))
    b.write_text("".join(rows_b))
    e = paired_over_steps(a, b, "APTKT", "random")
    assert e.n == 3 and e.mean == pytest.approx(0.03)
    # sd of (0.01, 0.02, 0.06) is 0.026458; t(0.975, 2) = 4.302653
    assert e.high - e.mean == pytest.approx(4.302653 * 0.0264575 / 3**0.5, rel=1e-4)
