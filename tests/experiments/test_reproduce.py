"""``aptkt reproduce`` end to end at the quick size, and the report's numbers come from results."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.experiments.figures import FIGURES, fig7, fig9
from aptkt.experiments.figures.base import STRESS_CUTOFF, STRESS_NO_CUTOFF, Context
from aptkt.experiments.figures.common import prior_groups
from aptkt.experiments.reproduce import _paper_numbers
from aptkt.experiments.scale import Scale
from aptkt.learning import LearnerConfig, PriorKnowledge

FILES = {
    "fig6": ["fig6.png", "fig6.svg", "results.csv", "curves.csv", "specs.jsonl", "report.md"],
    "fig7": ["fig7.png", "fig7.svg", "results.csv", "curves.csv", "specs.jsonl", "report.md"],
    "fig8": ["fig8.png", "fig8.svg", "results.csv", "curves.csv"],
    "fig9": ["fig9.png", "fig9.svg", "results.csv", "curves.csv"],
    "fig10": ["fig10.png", "fig10.svg", "confusion.csv", "dissimilar.json"],
    "fig11": ["fig11.png", "fig11.svg", "results.csv", "curves.csv"],
}


def read(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_every_figure_writes_its_files_and_report(quick_run):
    for fig, names in FILES.items():
        for name in names:
            assert (quick_run / fig / name).stat().st_size > 0, f"{fig}/{name}"
    report = (quick_run / "report.md").read_text()
    for fig in FIGURES:
        assert f"## {fig}:" in report
    assert "## Where this run differs from the paper" in report
    config = json.loads((quick_run / "config.json").read_text())
    assert config["seed"] == 0 and config["quick"] is True
    assert config["scale"]["name"] == "quick" and config["software_version"]
    assert "--seed 0" in config["repeat_with"]
    # The paper's layout: Fig. 11 has one panel per action and one for all actions; beyond it,
    # the stress panel (λ = 1 from the least related prior, with and without the cut-off).
    curves = read(quick_run / "fig11" / "curves.csv")
    assert {r["panel"] for r in curves} == set(Scale.quick().actions) | {"all", "stress"}
    assert {r["method"] for r in curves if r["panel"] == "stress"} == {
        "baseline",
        "APTKT",
        STRESS_CUTOFF,
        STRESS_NO_CUTOFF,
    }
    fig11_report = (quick_run / "fig11" / "report.md").read_text()
    assert "transfer rate" in fig11_report and "stress" in fig11_report
    # The stress runs with the cut-off never transfer more than those without it.
    rows = read(quick_run / "fig11" / "results.csv")
    taken = defaultdict(int)
    for r in rows:
        if r["panel"] == "stress":
            taken[r["method"]] += int(r["transfers"])
    assert taken[STRESS_CUTOFF] <= taken[STRESS_NO_CUTOFF]
    assert taken[STRESS_NO_CUTOFF] > 0  # without the cut-off, something is always transferred
    # Each step counts the models fitted and those in the prior's feature space: never for the
    # baseline, always for the control.
    assert "models in the prior's space" in fig11_report
    fig7_rows = read(quick_run / "fig7" / "results.csv")
    for r in rows + fig7_rows:
        assert int(r["updates"]) >= 1 and 0 <= int(r["prior_space"]) <= int(r["updates"])
        if r["method"] == "baseline":
            assert int(r["prior_space"]) == 0
        if r["method"] == "control":
            assert int(r["prior_space"]) == int(r["updates"])
    assert {r["method"] for r in fig7_rows} >= {"baseline", "control"}


def test_per_trial_bookkeeping_in_the_results(quick_run):
    s = Scale.quick()
    rows = read(quick_run / "fig7" / "results.csv")
    runs = defaultdict(list)
    for r in rows:
        runs[(r["method"], r["group"], r["run"])].append(int(r["step"]))
    methods = {"baseline", "control", "APTKT"}
    assert len(runs) == len(methods) * s.groups * s.trials
    assert {m for m, _, _ in runs} == methods
    # Every classifier's fitted hyper-parameters are columns of the results.
    assert any(k.startswith("hp[") and k.endswith("].signal_variance") for k in rows[0])
    assert all(float(r["median_length_scale"]) > 0 for r in rows)
    # The baseline uses nothing of the prior, so it never transfers; nor does the control.
    assert all(int(r["transfers"]) == 0 for r in rows if r["method"] in ("baseline", "control"))
    # One source per transferring decision.
    assert all(int(r["sources"]) == int(r["transfers"]) for r in rows)
    assert all(sorted(v) == list(range(s.budget + 1)) for v in runs.values())
    specs = [
        json.loads(line) for line in (quick_run / "fig7" / "specs.jsonl").read_text().splitlines()
    ]
    assert len(specs) == len(runs)
    # A trial's baseline and APTKT runs share the pool order and the exploration seed.
    by_trial = defaultdict(set)
    for sp in specs:
        by_trial[(sp["tags"]["group"], sp["tags"]["run"])].add(sp["pool_seed"])
    assert all(len(v) == 1 for v in by_trial.values()) and len(by_trial) == s.groups * s.trials
    # Fig. 6: every model of a trial saw the same observations (random order, same seed).
    rows6 = read(quick_run / "fig6" / "results.csv")
    seen = defaultdict(set)
    for r in rows6:
        if r["step"] != "0":
            seen[(r["panel"], r["group"], r["run"], r["step"])].add((r["action"], r["object"]))
    assert seen and all(len(v) == 1 for v in seen.values())


def test_report_gain_is_computed_from_the_results_file(quick_run):
    """Recompute Fig. 7's headline gain from results.csv independently and find it in the report."""
    rows = read(quick_run / "fig7" / "results.csv")
    acc = {
        (r["method"], int(r["group"]), int(r["run"]), int(r["step"])): float(r["mean_accuracy"])
        for r in rows
    }
    per_group = defaultdict(list)
    for (m, g, t, step), v in acc.items():
        if m == "APTKT":
            per_group[g].append(v - acc[("baseline", g, t, step)])
    gain = np.mean([np.mean(v) for v in per_group.values()])  # equal trials x steps per group
    summary = json.loads((quick_run / "summary.json").read_text())
    assert summary["numbers"]["fig7"]["gain"]["overall"]["mean"] == pytest.approx(gain, abs=1e-12)
    report = (quick_run / "report.md").read_text()
    assert f"{100 * gain:+.1f} pp [" in report


def test_fig11_control_and_fig8_room_are_computed_from_the_results_file(quick_run):
    """Fig. 11 runs the control (the prior's space, no transfer) in every setting, and its
    reported gap to the baseline is the one in results.csv; Fig. 8's share of the baseline's
    error removed likewise."""
    summary = json.loads((quick_run / "summary.json").read_text())["numbers"]
    rows = read(quick_run / "fig11" / "results.csv")
    acc = defaultdict(dict)
    for r in rows:
        if r["panel"] != "stress":
            acc[(r["panel"], r["method"], r["run"])][int(r["step"])] = float(r["mean_accuracy"])
    panels = {p for p, _, _ in acc}
    assert panels == set(Scale.quick().actions) | {"all"}
    for panel in panels:
        trials = sorted({t for p, m, t in acc if p == panel and m == "control"})
        assert trials == sorted({t for p, m, t in acc if p == panel and m == "baseline"})
        gaps = [
            np.mean([acc[(panel, "control", t)][s] - acc[(panel, "baseline", t)][s] for s in steps])
            for t in trials
            for steps in [sorted(acc[(panel, "baseline", t)])]
        ]
        reported = summary["fig11"]["control_vs_baseline"][panel]["overall"]["mean"]
        assert reported == pytest.approx(np.mean(gaps), abs=1e-12), panel
    assert all(int(r["transfers"]) == 0 for r in rows if r["method"] == "control")

    rows8 = read(quick_run / "fig8" / "results.csv")
    by = defaultdict(list)
    for r in rows8:
        if r["panel"] == "P2":
            by[r["method"]].append(float(r["mean_accuracy"]))
    base, aptkt = np.mean(by["baseline"]), np.mean(by["APTKT"])
    room = summary["fig8"]["baseline_error_removed"]["P2"]["curve"]
    assert room["baseline"] == pytest.approx(base, abs=1e-12)
    assert room["share"] == pytest.approx((aptkt - base) / (1 - base), abs=1e-12)


def test_rerun_resumes_everything_and_gives_the_same_results(quick_run, capsys):
    before = (quick_run / "fig9" / "results.csv").read_text()
    assert (
        main(
            [
                "reproduce",
                "fig9",
                "--quick",
                "--output",
                str(quick_run),
                "--jobs",
                "2",
                "--no-progress",
            ]
        )
        == 0
    )
    assert "0 computed now" in capsys.readouterr().out
    assert (quick_run / "fig9" / "results.csv").read_text() == before


def enough_groups() -> Scale:
    """The quick size with 4 groups: verdicts need at least 3 (2 support none)."""
    return dataclasses.replace(Scale.quick(), groups=4)


def hand_made_context(scale: Scale, output: Path) -> Context:
    """A reproduction's context for analysing hand-made rows (no data set behind it)."""
    return Context(
        scale=scale,
        seed=0,
        data="",
        fingerprint="",
        output=output,
        index=_paper_numbers(scale.objects),
    )


def hand_made_rows(gain: float, noise: float = 0.0, control: float | None = None):
    s = enough_groups()
    rng = np.random.default_rng(0)
    rows = []
    for g in range(s.groups):
        for t in range(s.trials):
            for step in range(s.budget + 1):
                base = 0.5 + 0.02 * step
                eps = noise * rng.normal()
                methods = [("baseline", base), ("APTKT", base + gain + eps)]
                if control is not None:
                    methods.append(("control", base + control))
                for m, v in methods:
                    rows.append(
                        {
                            "method": m,
                            "panel": "all",
                            "group": g,
                            "run": t,
                            "step": step,
                            "mean_accuracy": v,
                            "fused_accuracy": v,
                            "decisions": 9 if step == 0 else 3,
                            "transfers": 3 if m == "APTKT" else 0,
                        }
                    )
    return rows


@pytest.mark.parametrize(
    "gain, expected", [(0.10, "agrees"), (0.30, "more than twice"), (-0.10, "worse")]
)
def test_report_numbers_follow_hand_made_results(tmp_path, gain, expected):
    scale = enough_groups()
    ctx = hand_made_context(scale, tmp_path)
    section = fig7.analyse(ctx, hand_made_rows(gain, noise=0.01))
    head = section.headlines[0]
    measured = section.numbers["gain"]["overall"]["mean"]
    assert measured == pytest.approx(gain, abs=0.01)
    assert f"{100 * measured:+.1f} pp" in head.ours
    assert expected in head.verdict
    # Per run: 3 transfers at each of budget + 1 steps, out of 9 decisions at step 0 and 3 later.
    assert section.numbers["transfer_rate"] == pytest.approx(
        3 * (scale.budget + 1) / (9 + 3 * scale.budget)
    )
    assert (tmp_path / "fig7" / "fig7.svg").exists()
    assert not math.isnan(section.numbers["fused_gain"]["overall"]["mean"])


def test_fig9_explains_the_fade_and_the_auxiliary_features(tmp_path):
    """The fade's explanation reports the transferred priors' λ, the auxiliary features' verdict
    plain APTKT's start."""
    scale = dataclasses.replace(enough_groups(), trials=3)  # the one group of 4 priors: 3 runs
    ctx = hand_made_context(scale, tmp_path)
    rng = np.random.default_rng(1)
    rows = []
    for n in scale.prior_counts:
        lam = 0.8 if n == min(scale.prior_counts) else 0.6
        for g in range(len(prior_groups(ctx, n))):
            for t in range(scale.trials):
                for step in range(scale.budget + 1):
                    base = 0.5 + 0.02 * step
                    plain = base + 0.05
                    for m, v in (
                        ("baseline", base),
                        ("APTKT", plain),
                        ("APTKT+aux", plain + 0.03 + 0.002 * rng.normal()),
                    ):
                        transfers = 0 if m == "baseline" else 2
                        rows.append(
                            {
                                "method": m,
                                "n_priors": n,
                                "group": g,
                                "run": t,
                                "step": step,
                                "mean_accuracy": v,
                                "fused_accuracy": v,
                                "decisions": 3,
                                "transfers": transfers,
                                "sources": transfers,
                                "mean_lambda": lam if transfers else float("nan"),
                            }
                        )
    section = fig9.analyse(ctx, rows)
    fade = next(h for h in section.headlines if "fades" in h.claim)
    # The same gain and rate with more priors: the claim differs, and says what λ did.
    assert not fade.agrees and "averages 0.80 with 2 and 0.60 with 4 priors" in fade.why
    assert section.numbers["mean_lambda"] == {2: pytest.approx(0.8), 4: pytest.approx(0.6)}
    aux = next(h for h in section.headlines if "auxiliary features beat" in h.claim)
    assert aux.agrees and "+5.0 pp with 2, +5.0 pp with 4 priors" in aux.why


def test_fig7_splits_its_gain_into_the_space_and_the_transfer(tmp_path):
    scale = enough_groups()
    ctx = hand_made_context(scale, tmp_path)
    head = fig7.analyse(ctx, hand_made_rows(0.30, control=0.22)).headlines[0]
    assert "more than twice" in head.verdict
    assert "accounts for +22.0 pp" in head.why and "APTKT − control) for +8.0 pp" in head.why
    assert fig7.analyse(ctx, hand_made_rows(0.30)).headlines[0].why == ""


def test_quick_report_gives_no_verdict_it_cannot_support(quick_run):
    """2 groups / 2 runs per setting: every gain verdict of the quick report is withheld."""
    report = (quick_run / "report.md").read_text()
    assert "too few runs to judge" in report and "Not judged" in report
    assert "differs: no significant gain" not in report
    assert "–100 %" not in report.replace("0–100 %", "") and "(none)" not in report
    assert "Per-action average" in report


def test_figures_name_objects_and_show_chance_and_bands(quick_run):
    for fig in ("fig6", "fig7", "fig8", "fig9", "fig11"):
        svg = (quick_run / fig / f"{fig}.svg").read_text()
        assert "chance" in svg and "95 % interval" in svg, fig
    fig7_svg = (quick_run / "fig7" / "fig7.svg").read_text()
    assert "rough sponge" in fig7_svg or "paper box" in fig7_svg  # panels name their priors
    assert fig7_svg.count("accuracy") >= 3  # small panels have axis labels too
    fig10_svg = (quick_run / "fig10" / "fig10.svg").read_text()
    assert "row: observations of this object" in fig10_svg
    assert "column: assigned to this object" in fig10_svg and "smooth sponge" in fig10_svg


def test_the_papers_reading_reaches_every_model_and_the_record(tmp_path, quick_data):
    """--reading paper: recorded in config.json and in the report's command line, every run's
    learner is the paper's reading, and the prior files are built with it (per-classifier ML-II
    in the old objects' spread)."""
    out = tmp_path / "t"
    argv = ["reproduce", "fig7", "--quick", "--data", str(quick_data), "-o", str(out)]
    assert main([*argv, "--reading", "paper", "--jobs", "1", "--no-progress"]) == 0
    config = json.loads((out / "config.json").read_text())
    assert LearnerConfig.from_dict(config["learner"]) == LearnerConfig.paper()
    assert "--reading paper" in (out / "report.md").read_text()
    priors = list((out / "priors").glob("*.npz"))
    assert priors
    for path in priors:
        prior = PriorKnowledge.load(path)
        assert prior.feature_scale == "spread"
        assert {prior[a].model.kernel for a in prior.actions} == {"per-classifier"}
    with (out / "fig7" / "specs.jsonl").open() as fh:
        specs = [json.loads(line) for line in fh]
    configs = [LearnerConfig.from_dict(s["config"]) for s in specs]
    assert all(c.gp == LearnerConfig.paper().gp for c in configs)
    assert {c.cutoff for c in configs} == {"paper"}


@pytest.mark.slow
def test_the_prior_feature_scale_option_reaches_the_prior_files(tmp_path, quick_data):
    """--prior-feature-scale: the prior files' transforms whiten the within-object noise (the
    default: each modality, then across them) or divide by each column's spread (recorded in
    config.json and the command line)."""
    out = tmp_path / "n"
    argv = ["reproduce", "fig7", "--quick", "--data", str(quick_data), "-o", str(out)]
    assert main([*argv, "--prior-feature-scale", "spread", "--jobs", "1", "--no-progress"]) == 0
    learner = json.loads((out / "config.json").read_text())["learner"]
    assert learner["gp"]["prior_feature_scale"] == "spread"
    assert "--prior-feature-scale spread" in (out / "report.md").read_text()
    spread_priors = list((out / "priors").glob("*.npz"))
    assert spread_priors
    for path in spread_priors:
        prior = PriorKnowledge.load(path)
        for a in prior.actions:
            force = prior[a].pipeline.transforms.get("force")
            if force is not None:
                assert np.allclose(force.scale_, prior[a].observations.modalities["force"].std(0))
    out = tmp_path / "d"
    argv = ["reproduce", "fig7", "--quick", "--data", str(quick_data), "-o", str(out)]
    assert main([*argv, "--jobs", "1", "--no-progress"]) == 0
    config = json.loads((out / "config.json").read_text())
    assert config["learner"]["gp"]["prior_feature_scale"] == "whiten-joint"
    assert "--prior-feature-scale" not in (out / "report.md").read_text()
    priors = list((out / "priors").glob("*.npz"))
    assert priors
    for path in priors:
        prior = PriorKnowledge.load(path)
        for a in prior.actions:
            obs = prior[a].observations
            name = "force" if "force" in obs.modalities else "texture"
            transform = prior[a].pipeline.transforms[name]
            X = transform._prepare(obs.modalities[name])
            objects = obs.objects
            resid = np.vstack(
                [X[objects == o] - X[objects == o].mean(axis=0) for o in set(objects)]
            )
            dof = len(X) - len(set(objects))
            expected = np.sqrt((resid**2).sum(axis=0) / dof)
            assert np.allclose(transform.scale_, expected), (path.name, a)
            # ... and across the modalities: the whole action's within-object noise is less
            # correlated after the joint step than before it (its correlations were shrunk
            # before they were removed, so strong ones are weakened, not removed).
            joint = prior[a].pipeline.joint_
            assert joint is not None, (path.name, a)
            Z = prior[a].pipeline.transform(obs)[0]

            def largest_correlation(Z, objects=objects):
                R = np.vstack(
                    [Z[objects == o] - Z[objects == o].mean(axis=0) for o in set(objects)]
                )
                corr = np.corrcoef(R.T)
                return np.abs(corr[~np.eye(len(corr), dtype=bool)]).max()

            before = Z @ np.linalg.inv(joint).T
            assert largest_correlation(Z) < largest_correlation(before), (path.name, a)


def test_the_simulated_gains_are_set_beside_a_real_benchmarks(quick_run, tmp_path):
    """The comparison with a real-data benchmark (``--real-data``), from hand-made summaries:
    the ratios are the simulated gains over the real ones, and the report shows the rows that
    summary.json keeps."""
    from aptkt.experiments.beside_real import COLUMNS, beside_real, comparison, load_benchmark
    from aptkt.experiments.report import markdown_table

    numbers = {"fig7": {"gain": {"at_step": {"0": {"mean": 0.22}}, "overall": {"mean": 0.09}}}}

    def gains(values):
        return {"APTKT": [{"mean": v} for v in values]}

    real = {
        "table": "mine.csv",
        "command": "aptkt benchmark mine.csv",
        "objects": 20,
        "results": {
            "random": {
                "groups": 60,
                "gain": gains([0.11, 0.05, 0.02]),
                "mean": {"APTKT": [0.80, 0.85, 0.84], "baseline": [0.70, 0.71, 0.75]},
            },
            "farthest": {"gain": gains([0.09, -0.01, 0.0]), "mean": {"APTKT": [0.8, 0.9]}},
        },
    }
    rows = comparison(numbers, real)
    assert rows[0][1:] == ["+22.0 pp", "+11.0 pp", "2.0×"]
    assert rows[1][1:] == ["+9.0 pp", "+6.0 pp", "1.5×"]  # over the curve: mean of 11, 5, 2
    assert rows[2][2] == "-1.0 pp"  # least similar priors' lowest step
    assert rows[3][2] == "1.0 pp"  # APTKT's 0.85 -> 0.84, the largest fall
    assert markdown_table(list(COLUMNS), rows) in "\n".join(beside_real(real, rows))
    # As the benchmark writes it, per library size: the smallest library is compared.
    per_size = {**real, "results": {"10": {"random": {}}, "3": real["results"]}}
    (tmp_path / "summary.json").write_text(json.dumps(per_size))
    read = load_benchmark(tmp_path)
    assert read["library"] == 3 and comparison(numbers, read) == rows
    assert "3 prior objects" in "\n".join(beside_real(read, rows))
    # Without real data the summary says so, and the report says how to get it.
    assert json.loads((quick_run / "summary.json").read_text())["beside_real"] is None
    assert "--real-data DIR" in (quick_run / "report.md").read_text()
