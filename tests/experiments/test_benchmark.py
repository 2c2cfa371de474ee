"""The real-data benchmark on a small synthetic feature table: the protocol (splits, prior
choices, pairing), the numbers it reports against recomputations from its own results, the
checks, and its command line."""

from __future__ import annotations

import csv
import json
import re
from collections import defaultdict

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.experiments import benchmark_report as br
from aptkt.experiments import selection_report as sr
from aptkt.experiments.benchmark import (
    BenchmarkSettings,
    object_distances,
    prior_choices,
    split_trials,
)
from aptkt.learning import Observations
from aptkt.learning.feature_table import read_feature_table, write_feature_table

N_OBJECTS, N_TRIALS = 8, 8


def _table(tmp_path, suffix=".csv"):
    """8 objects on a line in one modality (object k at 3k), noise 1, one action; a second
    modality of pure noise."""
    rng = np.random.default_rng(0)
    objects = np.repeat([f"o{k}" for k in range(N_OBJECTS)], N_TRIALS)
    centre = np.repeat(3.0 * np.arange(N_OBJECTS), N_TRIALS)
    shape = np.column_stack([centre, np.zeros_like(centre)]) + rng.normal(size=(objects.size, 2))
    noise = rng.normal(size=(objects.size, 1))
    trials = np.tile(np.arange(N_TRIALS), N_OBJECTS)
    obs = Observations("touch", {"shape": shape, "noise": noise}, objects, trials)
    return write_feature_table(tmp_path / f"table{suffix}", {"touch": obs})


def test_each_object_learns_from_its_first_half_and_is_tested_on_its_second(tmp_path):
    table = read_feature_table(_table(tmp_path))
    learn, test = split_trials(table, ["touch"])
    assert learn.sum() == test.sum() == N_OBJECTS * N_TRIALS // 2
    for obj in table.object_names:
        rows = table.rows_of(obj, "touch")
        assert set(table.trials[rows[learn[rows]]]) == {0, 1, 2, 3}
        assert set(table.trials[rows[test[rows]]]) == {4, 5, 6, 7}


def test_priors_are_chosen_at_random_nearest_and_farthest_by_noise_levels(tmp_path):
    table = read_feature_table(_table(tmp_path))
    learn, _ = split_trials(table, ["touch"])
    names, d = object_distances(table.observations(["touch"], learn))
    # Objects 3 apart in units of noise 1 (the noise column adds a little).
    i, j = names.index("o0"), names.index("o1")
    assert 2.0 < d[i, j] < 4.5 and d[i, j] < d[i, names.index("o5")]
    new = ["o0", "o1"]
    rest = [f"o{k}" for k in range(2, N_OBJECTS)]
    both = prior_choices(new, rest, [2, 4], (names, d), np.random.default_rng(0))
    got = both[2]
    assert set(got["nearest"]) == {"o2", "o3"} and set(got["farthest"]) == {"o6", "o7"}
    assert len(set(got["random"])) == 2 and set(got["random"]) <= set(rest)
    # A library that grows: the larger one holds the smaller one, whichever way it is chosen.
    for choice in ("random", "nearest", "farthest"):
        assert set(got[choice]) <= set(both[4][choice]) and len(set(both[4][choice])) == 4


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    table = _table(out)
    argv = ["benchmark", str(table), "-o", str(out / "b"), "--groups", "3", "--new", "3"]
    argv += ["--priors", "2,3", "--budget", "2", "-j", "1", "--no-progress"]
    assert main(argv) == 0
    return out / "b"


def _rows(path):
    with open(path / "results.csv") as fh:
        return list(csv.DictReader(fh))


def test_every_method_runs_for_every_group_library_and_prior_choice(run):
    rows = _rows(run)
    runs = defaultdict(list)
    for r in rows:
        runs[(r["group"], r["library"], r["priors"], r["method"])].append(int(r["step"]))
    assert {k[1] for k in runs} == {"2", "3"}
    assert {k[2] for k in runs} == {"random", "nearest", "farthest"}
    methods = {"baseline", "APTKT", "APTKT+aux", "control", "1-NN", "1-NN shrunk"}
    # With random priors at the smallest library every learner also picks at random: its own
    # choice's reference.
    picks = {f"{m} random" for m in ("baseline", "APTKT", "APTKT+aux", "control")}
    for choice in ("random", "nearest", "farthest"):
        for size in ("2", "3"):
            got = {k[3] for k in runs if k[2] == choice and k[1] == size}
            assert got == (methods | picks if (choice, size) == ("random", "2") else methods)
    assert len(runs) == 3 * (2 * 3 * len(methods) + len(picks))
    for (_, _, _, method), steps in runs.items():
        assert sorted(steps) == ([0] if method.startswith("1-NN") else [0, 1, 2])
    # The baseline uses no prior: one run serves every library and choice of a group.
    for g in ("0", "1", "2"):
        curves = defaultdict(list)
        for r in rows:
            if r["group"] == g and r["method"] == "baseline":
                curves[(r["library"], r["priors"])].append(r["accuracy"])
        assert len(curves) == 6 and len({tuple(v) for v in curves.values()}) == 1
    # The libraries grow: a group's larger library holds its smaller one.
    for g in ("0", "1", "2"):
        for choice in ("random", "nearest", "farthest"):
            libs = {
                r["library"]: set(r["prior_objects"].split(","))
                for r in rows
                if r["group"] == g and r["priors"] == choice
            }
            assert libs["2"] < libs["3"]


def test_the_reported_gains_are_the_paired_means_of_the_results(run):
    rows = _rows(run)
    summary = json.loads((run / "summary.json").read_text())
    for size, choice in (("2", "random"), ("3", "nearest"), ("3", "farthest")):
        acc = defaultdict(dict)
        for r in rows:
            if r["priors"] == choice and r["step"] == "0" and r["library"] == size:
                acc[r["method"]][r["group"]] = float(r["accuracy"])
        d = [acc["APTKT"][g] - acc["baseline"][g] for g in sorted(acc["APTKT"])]
        gain = summary["results"][size][choice]["gain"]["APTKT"][0]
        assert gain["mean"] == pytest.approx(np.mean(d))
        half = 4.303 * np.std(d, ddof=1) / np.sqrt(3)  # Student's t, 2 degrees of freedom
        assert gain["high"] - gain["mean"] == pytest.approx(half)
        assert gain["n"] == 3 and gain["unit"] == "groups"
    report = (run / "report.md").read_text()
    assert "## Checks" in report and "1-NN" in report
    assert (run / "benchmark.png").stat().st_size > 0 and (run / "benchmark.svg").exists()
    assert "## How the data's noise looks" in report and len(summary["noise_profile"]) == 2
    assert summary["learner"]["gp"]["kernel"] == "library"
    assert summary["libraries"] == [2, 3]
    assert "## Gain against library size (random priors)" in report
    assert (run / "library.png").stat().st_size > 0


def test_each_learner_is_compared_with_its_own_random_picks(run):
    """The random-picks arms start where the active ones do (the same first observations) and
    the reported gains and touches are recomputed from results.csv."""
    rows = _rows(run)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["selection"] == "error-reduction"
    acc = defaultdict(lambda: defaultdict(dict))
    for r in rows:
        if r["priors"] == "random" and r["library"] == "2":
            acc[r["method"]][int(r["group"])][int(r["step"])] = float(r["accuracy"])

    def matrix(method):
        return np.array([[acc[method][g][k] for k in range(3)] for g in sorted(acc[method])])

    found = {(e["learner"], e["library"]): e for e in summary["active_against_random"]}
    # APTKT+aux is left out where it learned exactly as APTKT.
    assert {"baseline", "APTKT", "control"} <= {k[0] for k in found}
    for learner in ("baseline", "APTKT", "control"):
        active, random = matrix(learner), matrix(f"{learner} random")
        np.testing.assert_array_equal(active[:, 0], random[:, 0])
        e = found[(learner, 2)]
        assert e["mean_gain"]["mean"] == pytest.approx(np.mean((active - random)[:, 1:]))
        assert e["budget"] == 2 and e["groups"] == 3
        touches = sr.touches_to_reach(active, random)
        assert e["touches"] == (None if np.isnan(touches) else pytest.approx(touches))
    report = (run / "report.md").read_text()
    assert "## Active choice against random picks" in report
    assert (run / "selection.png").stat().st_size > 0 and (run / "selection.svg").exists()


def test_the_estimate_is_set_against_held_out_and_same_period_touches(run):
    """summary.json's calibration, recomputed from results.csv: the learner's own estimate
    against its held-out accuracy and against its accuracy on the pool's unused touches."""
    rows = _rows(run)
    summary = json.loads((run / "summary.json").read_text())
    found = {(e["learner"], e["library"]): e for e in summary["own_estimate"]}
    assert ("APTKT", 2) in found and ("baseline", 2) in found
    for (learner, size), e in found.items():
        per = defaultdict(dict)
        for r in rows:
            if (r["method"], r["library"], r["priors"]) == (learner, str(size), "random"):
                per[int(r["step"])][int(r["group"])] = r
        for k, est, held, same in zip(e["steps"], e["estimated"], e["held_out"], e["same_period"]):
            judged = [r for r in per[k].values() if r["estimated"] not in ("", "nan")]
            assert est == pytest.approx(np.mean([float(r["estimated"]) for r in judged]))
            assert held == pytest.approx(np.mean([float(r["accuracy"]) for r in judged]))
            assert same == pytest.approx(np.mean([float(r["same_period"]) for r in judged]))
        error = np.mean(np.abs(np.subtract(e["estimated"], e["same_period"])))
        assert e["same_period_mean_absolute_error"] == pytest.approx(error)
    assert "accuracy on the pool's touches not drawn" in (run / "report.md").read_text()
    # It costs a prediction per step, so the runs no calibration reads leave it out.
    for r in rows:
        read = r["priors"] == "random" and r["method"] in {learner for learner, _ in found}
        if r["method"] in ("control", "APTKT random", "baseline random"):
            assert r["same_period"] in ("", "nan"), r
        elif read:
            assert r["same_period"] not in ("", "nan"), r


def test_the_touches_needed_are_where_the_active_curve_crosses_randoms_end():
    random = np.array([[0.5, 0.6, 0.7, 0.8], [0.5, 0.6, 0.7, 0.8]])
    # The active mean reaches 0.8 halfway between steps 1 (0.7) and 2 (0.9).
    active = np.array([[0.5, 0.7, 0.9, 0.9], [0.5, 0.7, 0.9, 0.95]])
    assert sr.touches_to_reach(active, random) == pytest.approx(1.5)
    assert sr.touches_to_reach(random, random) == pytest.approx(3.0)
    assert np.isnan(sr.touches_to_reach(random - 0.1, random))
    assert sr.touches_to_reach(random + 0.5, random) == 0.0
    c = {3: {"random": {"APTKT": active, "APTKT random": random}}}
    (r,) = sr.compare(c)
    assert r.touches == pytest.approx(1.5) and r.saved == pytest.approx(0.5)
    assert r.lowest == pytest.approx(0.1) and r.lowest_step == 1 and r.largest_fall == 0.0
    assert r.touches_low <= r.touches <= r.touches_high
    (check,) = sr.checks([r])
    assert check.holds and check.kind == "reference"
    (dip,) = sr.checks(
        sr.compare(
            {3: {"random": {"APTKT": random - 0.006 * (np.arange(4) > 0), "APTKT random": random}}}
        )
    )
    assert not dip.holds


def test_the_nearest_neighbour_reference_is_the_plain_rule(run):
    """1-NN on the first observation of each new object, in the prior's space, recomputed
    from the learner's own one-shot observations is what the results hold."""
    from aptkt.experiments.benchmark import _subset, nearest_neighbour_accuracy
    from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment, PriorKnowledge

    rows = _rows(run)
    table = read_feature_table(run.parent / "table.csv")
    learn_rows, test_rows = split_trials(table, ["touch"])
    learn = table.observations(["touch"], learn_rows)
    test = table.observations(["touch"], test_rows)
    r0 = next(
        r for r in rows if r["method"] == "1-NN" and r["group"] == "0" and r["library"] == "2"
    )
    new, priors = r0["new_objects"].split(","), r0["prior_objects"].split(",")
    seed = 0  # the benchmark's seed for group 0 with --seed 0
    base = APTKT(LearnerConfig(transfer="none", budget=0, seed=seed))
    base.run(PoolEnvironment(_subset(learn, new), seed=seed), ["touch"], new)
    first = {"touch": base.learners["touch"].observations}
    prior = PriorKnowledge.build(_subset(learn, priors))
    expected = nearest_neighbour_accuracy(prior, first, _subset(test, new))
    X = prior["touch"].pipeline.transform(first["touch"])[0]
    T = prior["touch"].pipeline.transform(_subset(test, new)["touch"])[0]
    nearest = first["touch"].objects[
        np.argmin(((T[:, None, :] - X[None, :, :]) ** 2).sum(-1), axis=1)
    ]
    assert expected == pytest.approx(np.mean(nearest == _subset(test, new)["touch"].objects))
    assert float(r0["accuracy"]) == pytest.approx(expected)
    # The shrunk-covariance rule, recomputed from the definition with scikit-learn's 1-NN.
    from sklearn.neighbors import KNeighborsClassifier

    from aptkt.learning.pipeline import within_object_residuals

    old = _subset(learn, priors)["touch"]

    def cols(o):
        return np.hstack([o.modalities[m] for m in o.modality_names])

    R, dof = within_object_residuals(cols(old), old.objects)
    C = R.T @ R / dof
    C = 0.8 * C + 0.2 * np.diag(np.diag(C))
    L = np.linalg.cholesky(np.linalg.inv(C))  # x ↦ Lᵀx whitens as C^(-1/2) does (up to rotation)
    knn = KNeighborsClassifier(1).fit(cols(first["touch"]) @ L, first["touch"].objects)
    held = _subset(test, new)["touch"]
    shrunk = np.mean(knn.predict(cols(held) @ L) == held.objects)
    r1 = next(
        r
        for r in rows
        if r["method"] == "1-NN shrunk" and r["group"] == "0" and r["library"] == "2"
    )
    assert float(r1["accuracy"]) == pytest.approx(shrunk)


def _curves(base, aptkt, aux=None, nn=0.5, falls=False, control=None, flat=False):
    n = 6
    rng = np.random.default_rng(1)
    steps = np.arange(4)
    rise = 0.0 if flat else 0.02
    c = {
        "baseline": np.tile(base + 0.02 * steps, (n, 1)) + 0.001 * rng.normal(size=(n, 4)),
        "APTKT": np.tile(aptkt + rise * steps, (n, 1)) + 0.001 * rng.normal(size=(n, 4)),
        "control": np.tile((aptkt if control is None else control) + rise * steps, (n, 1)),
        "1-NN": np.full((n, 1), nn),
        "1-NN shrunk": np.full((n, 1), nn),
    }
    c["APTKT+aux"] = c["APTKT"] + (0.0 if aux is None else aux)
    if falls:
        c["baseline"][:, 2] -= 0.05
    return {3: {"random": c, "farthest": {k: v.copy() for k, v in c.items()}}}


#: A failing claim's fragment and its kind: an invariant must hold on any data; a reference
#: figure (the paper's, the BioTac set's) is reported as reached or not.
INV, REF = br.INVARIANT, br.REFERENCE


@pytest.mark.parametrize(
    "curves, failing",
    [
        (_curves(0.6, 0.75), []),
        (_curves(0.6, 0.65), [("baseline + 10 pp", REF)]),
        (
            _curves(0.6, 0.75, nn=0.8),
            [("its own feature space", REF), ("shrunk covariance", REF)],
        ),
        (
            _curves(0.6, 0.55),
            [
                ("baseline + 10 pp", REF),
                ("least similar", INV),
                ("random priors: APTKT never below the baseline", INV),
                ("end of the budget", INV),
            ],
        ),
        (_curves(0.6, 0.75, aux=-0.01), [("auxiliary", INV)]),
        (_curves(0.6, 0.75, aux=-0.003), []),  # within the tolerance of an addition
        (_curves(0.6, 0.75, falls=True), [("unlearns", INV)]),
        (_curves(0.6, 0.75, control=0.76), [("never costs", INV)]),
        (_curves(0.6, 0.75, flat=True), [("keeps learning", REF)]),
    ],
)
def test_each_check_fails_exactly_when_its_claim_does(curves, failing):
    found = br.checks(curves)
    assert len(found) == 10
    failed = [k for k in found if not k.holds]
    assert len(failed) == len(failing), [k.claim for k in failed]
    for fragment, kind in failing:
        (check,) = [k for k in failed if fragment in k.claim]
        assert check.kind == kind, check
        assert check.verdict == ("not reached" if kind == REF else "fails")


def test_the_report_and_the_console_keep_invariants_apart_from_reference_figures():
    """A healthy run on a sensor unlike the paper's: every invariant holds, the one-shot
    reference is not reached. The report says so in two tables; the console line counts the
    invariants as checks and the references as figures reached."""
    found = br.checks(_curves(0.6, 0.65))
    table = br.checks_table(found, unit="6 groups")
    must, ref = table.split("### Reference figures")
    assert "### What must hold on any data" in must and "over 6 groups" in must
    assert "fails" not in must and "not reached" not in must
    assert "| not reached |" in ref and "baseline + 10 pp" in ref and "holds" not in ref
    said: list[str] = []
    assert br.announce_checks(found, said.append) == 6
    assert not any("FAILS" in line for line in said)
    assert any(line.startswith("  not reached: random priors: APTKT ≥ baseline") for line in said)
    assert br.checks_line(found) == "6 of 6 checks hold; 3 of 4 reference figures reached"


def test_the_figure_of_two_library_sizes_is_a_grid_no_wider_than_a_screen(tmp_path):
    """Two library sizes with three prior choices each: six panels in two rows of three, the
    saved image at most about 2,400 px wide (one row of six was 4,484 px)."""
    from matplotlib.image import imread

    from aptkt.experiments.plots import save_figure

    c = {3: _curves(0.6, 0.75)[3], 5: _curves(0.6, 0.78)[3]}
    c[3]["nearest"] = {k: v.copy() for k, v in c[3]["random"].items()}
    c[5]["nearest"] = {k: v.copy() for k, v in c[5]["random"].items()}
    fig = br.plot(c, chance=0.2)
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 12  # six panels, an accuracy and a gain axis each
    titles = [ax.get_title() for ax in visible if ax.get_title()]
    assert len(titles) == 6 and titles[0].startswith("3 random priors")
    (png, _svg) = save_figure(fig, tmp_path / "benchmark")
    height, width = imread(png).shape[:2]
    assert width <= 2400 and height > width / 2, (width, height)


def test_aptkt_aux_is_shown_only_where_it_learned_otherwise_than_aptkt():
    """On real data the auxiliary features' gate often stays shut and APTKT+aux repeats APTKT
    in every run: it is then left out of the plot and the tables, and the report says so."""
    same = _curves(0.6, 0.75)  # APTKT+aux is a copy of APTKT
    differs = _curves(0.6, 0.75, aux=0.01)

    def labels(c):
        fig = br.plot(c, chance=0.2)
        return {t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().texts}

    assert not any("APTKT+aux" in t for t in labels(same))
    assert {"APTKT+aux", "APTKT+aux − baseline"} <= labels(differs)
    note = "\n".join(br._aux_note(same))
    assert "learned exactly as plain APTKT" in note and "every library and prior choice" in note
    assert br._aux_note(differs) == []
    # One choice alike, the other not: named.
    mixed = {3: {"random": same[3]["random"], "farthest": differs[3]["farthest"]}}
    assert "with random priors:" in "\n".join(br._aux_note(mixed))
    assert [("APTKT+aux" in m) for _, _, m in br._panels(mixed)] == [False, True]


@pytest.mark.parametrize("large, holds", [(0.72, True), (0.69, False), (0.80, True), (0.70, True)])
def test_the_gain_must_not_shrink_as_the_library_grows(large, holds):
    """With several library sizes: the largest library's one-shot gain at least the smallest's
    − 1 pp (an invariant; +10 pp is each size's own reference figure)."""
    small = _curves(0.6, 0.71)[3]
    grown = _curves(0.6, large)[3]
    found = br.checks({3: small, 15: grown})
    growth = [k for k in found if "does not shrink" in k.claim]
    assert len(growth) == 1 and growth[0].holds is holds
    assert any(k.claim.startswith("15 random priors") for k in found)


def test_the_command_refuses_to_overwrite_and_reports_mistakes_in_one_line(run, tmp_path, capsys):
    table = run.parent / "table.csv"
    argv = ["benchmark", str(table), "-o", str(run), "--groups", "2"]
    assert main(argv) == 1
    assert "--force" in capsys.readouterr().err
    for extra, fragment in (
        (["--new", "1"], "--new must be >= 2"),
        (["--choices", "closest"], "--choices: closest"),
        (["--groups", "0"], "--groups must be >= 1"),
        # bounded as the other commands' counts (docs/reliability.md)
        (["--groups", "1000000"], "--groups must be at most 1000"),
        (["--budget", "1000000000"], "--budget must be at most 10000"),
        (["-j", "100000"], "--jobs must be at most"),
        (["--priors", "5,3"], "distinct and increasing"),
        (["--priors", "3,x"], "not a number"),
        (["--priors", "3,1"], "--priors must be >= 2"),
        (["--lifelong", "--groups", "5"], "--groups: not with --lifelong"),
        (["--orders", "0"], "--orders must be >= 1"),
        (["--actions", "touch,nope"], "--actions: unknown nope; the table has touch"),
    ):
        assert main(["benchmark", str(table), "-o", str(tmp_path / "x"), *extra]) == 1
        said = capsys.readouterr()
        err = said.err.strip()
        assert said.out == "", said.out  # nothing before the mistake's line
        assert err.count("\n") == 0 and err.startswith("aptkt benchmark: error:"), err
        assert fragment in err
    assert (
        main(["benchmark", str(table), "-o", str(tmp_path / "y"), "--new", "6", "--priors", "3"])
        == 1
    )
    said = capsys.readouterr()
    assert "need at least 9 objects" in said.err
    assert said.out == ""  # (the heading came first, then the mistake)
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    assert BenchmarkSettings().groups == 60


def test_strict_gates_on_invariants_and_strict_reference_also_on_reference_figures(
    run, tmp_path, capsys
):
    """One group of 3 new objects: the one-shot reference figure needs an interval above +5 pp
    and one group gives none, so it is not reached: --strict-reference fails the command,
    --strict fails it exactly when an invariant failed, and without either it succeeds; the
    results exist either way."""
    table = run.parent / "table.csv"
    base = ["benchmark", str(table), "--groups", "1", "--new", "3", "--priors", "2"]
    base += ["--budget", "1", "--choices", "random", "-j", "1", "--no-progress"]
    assert main([*base, "-o", str(tmp_path / "lax")]) == 0
    assert main([*base, "-o", str(tmp_path / "ref"), "--strict-reference"]) == 1
    err = capsys.readouterr().err
    assert "check(s) failed or not reached (--strict-reference)" in err
    summary = json.loads((tmp_path / "ref" / "summary.json").read_text())
    one_shot = [c for c in summary["checks"] if "baseline + 10 pp" in c["claim"]]
    assert [(c["kind"], c["verdict"]) for c in one_shot] == [("reference", "not reached")]
    assert (tmp_path / "ref" / "report.md").exists()
    invariant_failed = any(not c["holds"] for c in summary["checks"] if c["kind"] == "invariant")
    assert main([*base, "-o", str(tmp_path / "strict"), "--strict"]) == int(invariant_failed)


@pytest.mark.parametrize(
    "checks, strict, reference, code",
    [
        ([("invariant", True), ("reference", False)], True, False, 0),
        ([("invariant", True), ("reference", False)], True, True, 1),
        ([("invariant", False), ("reference", True)], True, False, 1),
        ([("invariant", False)], False, False, 0),
        ([("reference", True), ("invariant", True)], True, True, 0),
    ],
)
def test_strict_counts_only_the_kinds_it_is_asked_for(tmp_path, checks, strict, reference, code):
    from argparse import Namespace

    from aptkt.commands.benchmark import _strict_exit

    summary = {"checks": [{"claim": "c", "holds": h, "kind": k} for k, h in checks]}
    args = Namespace(strict=strict, strict_reference=reference, output=tmp_path)
    assert _strict_exit(args, summary) == code


def test_progress_goes_to_a_log_as_lines(run, tmp_path, capfd, monkeypatch):
    """Not a terminal: progress lines with the time spent and left on standard error (here
    at once: these groups take less than the pause that keeps quick work quiet)."""
    monkeypatch.setattr("aptkt.progress.LINE_AFTER_SECONDS", 0.0)
    table = run.parent / "table.csv"
    argv = [
        "benchmark",
        str(table),
        "--groups",
        "2",
        "--new",
        "3",
        "--priors",
        "2",
        "--budget",
        "0",
    ]
    assert main([*argv, "--choices", "random", "-j", "1", "-o", str(tmp_path / "p")]) == 0
    err = capfd.readouterr().err
    assert "benchmark: 1/2 groups (50 %)" in err and "left" in err
    assert "benchmark: 2/2 groups (100 %)" in err


def test_the_lifelong_benchmark_says_which_objects_no_batch_takes(tmp_path, capsys):
    """8 objects, batches of 3: a library of 3 and one batch of 3; the other 2 objects of each
    order are never learned, and the command says so before it starts."""
    path = _table(tmp_path)
    argv = ["benchmark", str(path), "--lifelong", "--orders", "1", "--new", "3", "--budget", "1"]
    assert main([*argv, "-j", "1", "--no-progress", "-o", str(tmp_path / "life")]) == 0
    said = capsys.readouterr().out
    assert "8 objects (each order leaves its last 2 out: 8 is not 3 plus whole batches of 3)" in (
        said
    )


def test_the_lifelong_benchmark_grows_a_library_and_reports_it(tmp_path, capsys):
    """8 objects in batches of 2: a library of 2, then three batches learned and merged; the
    library's accuracy is its identity model's on every object it holds, the reference the
    nearest class mean in its metric (both recomputed here)."""
    from aptkt.experiments.lifelong import (
        LifelongSettings,
        _orders,
        library_accuracy,
        nearest_class_mean_accuracy,
        run_order,
    )

    path = _table(tmp_path)
    out = tmp_path / "life"
    argv = ["benchmark", str(path), "--lifelong", "--orders", "2", "--new", "2", "--budget", "2"]
    assert main([*argv, "-j", "1", "--no-progress", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "2 orders: a library of 2, then 3 batch(es) of 2" in said
    assert "leaves" not in said
    rows = _rows(out)
    assert {r["method"] for r in rows} == {"baseline", "APTKT", "library", "library GP", "NCM"}
    sizes = sorted({(int(r["batch"]), int(r["library"])) for r in rows if r["method"] == "library"})
    assert sizes == [(1, 4), (2, 6), (3, 8)]
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["checks"]) == 3 and (out / "lifelong.png").stat().st_size > 0
    # The rows are what one order's run gives, recomputed.
    table = read_feature_table(path)
    learn_rows, test_rows = split_trials(table, ["touch"])
    learn = table.observations(["touch"], learn_rows)
    test = table.observations(["touch"], test_rows)
    s = LifelongSettings(orders=2, batch=2, budget=2)
    again = run_order(0, _orders(table.object_names, s)[0], learn, test, s)
    first = [r for r in rows if r["order"] == "0"]
    assert len(again) == len(first)
    for a, b in zip(sorted(again, key=lambda r: (r["batch"], r["method"], r["step"])), first):
        assert float(a["accuracy"]) == pytest.approx(float(b["accuracy"]))
    assert library_accuracy and nearest_class_mean_accuracy  # documented entry points


def test_nearest_class_mean_is_the_plain_rule():
    from aptkt.experiments.lifelong import library_accuracy, nearest_class_mean_accuracy
    from aptkt.learning import PriorKnowledge

    rng = np.random.default_rng(3)
    means = {"a": [0.0, 0.0], "b": [4.0, 0.0], "c": [0.0, 4.0]}
    objects = np.repeat(list(means), 10)
    X = np.array([means[o] for o in objects]) + rng.normal(size=(30, 2))
    lib = PriorKnowledge.build({"t": Observations("t", {"m": X}, objects)}, seed=0)
    T = np.array([means[o] for o in objects]) + rng.normal(size=(30, 2))
    test = {"t": Observations("t", {"m": T}, objects)}
    Z, Zt = (
        lib["t"].pipeline.transform(lib["t"].observations)[0],
        lib["t"].pipeline.transform(test["t"])[0],
    )
    centres = np.array([Z[objects == o].mean(axis=0) for o in "abc"])
    nearest = np.array(list("abc"))[((Zt[:, None] - centres[None]) ** 2).sum(-1).argmin(1)]
    assert nearest_class_mean_accuracy(lib, test) == pytest.approx(np.mean(nearest == objects))
    assert library_accuracy(lib, test) > 0.8


def test_a_dask_cluster_gives_the_same_benchmark(run, tmp_path):
    """--scheduler: the groups run on a Dask cluster and give the local run's rows."""
    from dask.distributed import LocalCluster

    table = run.parent / "table.csv"
    argv = ["benchmark", str(table), "--groups", "2", "--new", "3", "--priors", "2,3"]
    argv += ["--budget", "1", "--choices", "random", "--no-progress"]
    assert main([*argv, "-j", "1", "-o", str(tmp_path / "local")]) == 0
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        assert (
            main([*argv, "--scheduler", cluster.scheduler_address, "-o", str(tmp_path / "dask")])
            == 0
        )
    local, remote = _rows(tmp_path / "local"), _rows(tmp_path / "dask")
    assert len(local) == len(remote)
    for a, b in zip(local, remote):
        assert a == b


def test_the_recognition_benchmark_reports_accuracy_auroc_and_false_alarms(tmp_path, capsys):
    path = _table(tmp_path)
    out = tmp_path / "rec"
    argv = ["benchmark", str(path), "--recognition", "--priors", "5", "--new", "3", "--groups", "2"]
    assert main([*argv, "-j", "1", "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "novelty AUROC" in said and "nearest class mean" in said
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["results"]) >= {"accuracy", "ncm", "auroc", "false_alarms", "detected"}
    rows = _rows(out)
    assert len(rows) == 2 and all(len(r["library"].split(",")) == 5 for r in rows)
    assert main([*argv, "--priors", "3,5", "-o", str(tmp_path / "x")]) == 1
    assert "one library size" in capsys.readouterr().err


def test_a_recognition_benchmark_whose_libraries_hold_no_repeat_is_one_line(tmp_path, capsys):
    """3 trials per object: each library holds one touch of each object (the first half), so
    it knows no noise to judge by. One error line, and no warning before it."""
    import warnings

    rng = np.random.default_rng(0)
    objects = np.repeat([f"o{k}" for k in range(8)], 3)
    shape = np.repeat(3.0 * np.arange(8), 3)[:, None] + rng.normal(size=(24, 2))
    obs = Observations("touch", {"shape": shape}, objects, np.tile(np.arange(3), 8))
    path = write_feature_table(tmp_path / "three.csv", {"touch": obs})
    argv = ["benchmark", str(path), "--recognition", "--priors", "5", "--new", "3"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main([*argv, "--groups", "2", "-j", "1", "-o", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "aptkt benchmark: error: action 'touch': no object of the library was observed twice"
    ]


def _strict(text: str):
    def refuse(constant: str):
        raise AssertionError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def _estimates(value):
    if isinstance(value, dict):
        if {"mean", "low", "high", "n"} <= set(value):
            yield value
        for v in value.values():
            yield from _estimates(v)
    elif isinstance(value, list):
        for v in value:
            yield from _estimates(v)


@pytest.mark.parametrize(
    "extra",
    [
        ["--groups", "1", "--new", "3", "--priors", "2", "--budget", "1"],
        ["--lifelong", "--orders", "1", "--new", "2", "--budget", "1"],
        ["--recognition", "--groups", "1", "--new", "3", "--priors", "5"],
    ],
    ids=["benchmark", "lifelong", "recognition"],
)
def test_one_group_gives_strict_json_and_says_why_there_is_no_interval(run, tmp_path, extra):
    """An interval needs two groups (orders, draws): with one, summary.json holds null with the
    reason beside it, never a bare NaN, and report.md says why rather than printing nan."""
    out = tmp_path / "one"
    assert (
        main(["benchmark", str(run.parent / "table.csv"), *extra, "-j", "1", "-o", str(out)]) == 0
    )
    summary = _strict((out / "summary.json").read_text())
    found = list(_estimates(summary))
    assert found and all(e["low"] is None and e["high"] is None for e in found)
    assert all(e["no_interval"].startswith("1 ") for e in found)
    report = (out / "report.md").read_text()
    assert not re.search(r"\bnan\b", report, re.I) and "interval" in report


def test_trials_are_chosen_before_each_objects_trials_are_halved(tmp_path, monkeypatch, capsys):
    import aptkt.experiments.benchmark as benchmark

    given = {}

    def record(table, settings, **run):
        given.update(table=table, command=run["command"])
        return {"checks": []}

    monkeypatch.setattr(benchmark, "run_benchmark", record)
    table = _table(tmp_path)
    assert main(["benchmark", str(table), "--trials", "2-7", "-o", str(tmp_path / "b")]) == 0
    assert set(given["table"].trials.tolist()) == set(range(2, 8))
    assert len(given["table"].trials) == N_OBJECTS * 6
    assert given["command"].endswith("--trials 2-7")
    assert main(["benchmark", str(table), "--trials", "6-9", "-o", str(tmp_path / "c")]) == 1
    assert capsys.readouterr().err == (
        f"aptkt benchmark: error: --trials 6-9: trial(s) 8-9 not in {table} (it has trials 0-7)\n"
    )


def test_the_same_period_accuracy_weighs_every_object_once():
    """Against scikit-learn's balanced accuracy on the pool's unused touches (each object's
    recall, averaged), for each action, averaged over the actions."""
    from sklearn.metrics import balanced_accuracy_score

    from aptkt.experiments.benchmark import same_period_accuracy
    from aptkt.learning import APTKT, LearnerConfig, PoolEnvironment

    rng = np.random.default_rng(5)
    table = {}
    for action, spread in (("P", 1.0), ("S", 2.5)):
        objects = np.repeat(["a", "b", "c", "d"], 6)
        centre = np.repeat(np.arange(4.0), 6)[:, None] * np.array([[1.0, 0.5]])
        X = centre + spread * rng.normal(size=(24, 2))
        table[action] = Observations(action, {"m": X}, objects, np.tile(np.arange(6), 4))
    env = PoolEnvironment(table, seed=2)
    learner = APTKT(LearnerConfig(transfer="none", budget=3, seed=0))
    learner.run(env, ["P", "S"], ["a", "b", "c", "d"])
    want = []
    for action, lrn in learner.learners.items():
        unused = env.unused(action)
        classes = np.array([str(c) for c in lrn.model.classes_])
        predicted = classes[lrn.predict_proba(unused).argmax(axis=1)]
        want.append(balanced_accuracy_score(unused.objects.astype(str), predicted))
    assert same_period_accuracy(learner, env) == pytest.approx(np.mean(want))
