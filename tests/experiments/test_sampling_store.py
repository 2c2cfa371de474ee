"""Seeds, object groups, run keys and the store of finished runs."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from aptkt.experiments.priors import PriorTask
from aptkt.experiments.run_store import RunStore, run_key
from aptkt.experiments.runs import RunSpec
from aptkt.experiments.sampling import derive_seed, draw_groups
from aptkt.gp import DEFAULTS
from aptkt.learning import GPSettings, LearnerConfig


def test_derived_seeds_are_stable_and_independent():
    assert derive_seed(0, "trial", 3, 1, 2) == derive_seed(0, "trial", 3, 1, 2)
    seeds = {derive_seed(s, "trial", n, g) for s in (0, 1) for n in (3, 5) for g in range(10)}
    assert len(seeds) == 40
    assert all(0 <= s < 2**31 for s in seeds)
    with pytest.raises(ValueError):
        derive_seed(-1)


def test_groups_are_distinct_uniform_draws_in_library_order():
    objects = [f"o{i}" for i in range(10)]
    groups = draw_groups(objects, 3, 10, seed=7)
    assert len(groups) == 10 and len(set(groups)) == 10
    for g in groups:
        assert len(set(g)) == 3 and list(g) == sorted(g, key=objects.index)
    assert groups == draw_groups(objects, 3, 10, seed=7)
    assert groups != draw_groups(objects, 3, 10, seed=8)
    assert draw_groups(objects, 10, 10, seed=1) == [tuple(objects)]  # only one possible group
    assert len(draw_groups(objects[:4], 3, 10, seed=1)) == math.comb(4, 3)
    with pytest.raises(ValueError):
        draw_groups(objects, 11, 1, seed=0)


def test_groups_are_roughly_uniform():
    objects = list("abcdef")
    counts = {o: 0 for o in objects}
    for seed in range(300):
        for o in draw_groups(objects, 2, 1, seed)[0]:
            counts[o] += 1
    assert all(abs(c - 100) < 35 for c in counts.values())  # 600 picks over 6 objects


def spec(**changes):
    base = RunSpec(
        "APTKT",
        LearnerConfig(budget=3, seed=1),
        "/data/a.h5",
        ("P1",),
        ("x", "y"),
        (0, 1),
        (2,),
        prior="/out/priors/prior-3-abc.npz",
        pool_seed=1,
        tags={"figure": "fig7", "group": 0},
    )
    return replace(base, **changes)


def test_run_key_covers_what_changes_the_result_and_nothing_else():
    k = run_key(spec(), "fp")
    # Labels and file locations do not change a run's result.
    assert run_key(spec(method="other", tags={"figure": "fig9"}), "fp") == k
    assert run_key(spec(data="/elsewhere/a.h5", prior="/moved/prior-3-abc.npz"), "fp") == k
    # Everything else does.
    for changed in (
        spec(config=LearnerConfig(budget=4, seed=1)),
        spec(actions=("P2",)),
        spec(new_objects=("x", "z")),
        spec(pool_trials=(0,)),
        spec(test_trials=(3,)),
        spec(pool_seed=2),
        spec(prior=None),
        spec(prior="/out/priors/prior-3-abd.npz"),
    ):
        assert run_key(changed, "fp") != k
    assert run_key(spec(), "other data") != k


def test_every_learner_and_gp_setting_is_part_of_the_keys():
    """A store or a prior file is found again only under the settings that computed it: a
    resumed run must never hand out results computed another way. Every learner and GP setting
    changes the run key, every GP setting the prior file's key, and the records round-trip."""
    spec = RunSpec(
        method="APTKT",
        config=LearnerConfig(),
        data="/d/a.h5",
        actions=("P1", "S1"),
        new_objects=("a", "b"),
        pool_trials=(0, 1),
        test_trials=(2, 3),
        prior="/p/prior-3-abc.npz",
        pool_seed=5,
    )
    task = PriorTask(
        fingerprint="fp",
        data="/d/a.h5",
        objects=("x", "y", "z"),
        actions=("P1",),
        trials=(0, 1, 2),
        seed=3,
        directory="/p",
        gp=GPSettings().to_dict(),
    )
    base = run_key(spec, "fp")
    gp_changes = {
        "kernel": "per-classifier",
        "prior_feature_scale": "spread",
        "hyper_prior": None,
        "n_restarts": 1,
        "optimizer_tol": DEFAULTS.optimizer_tol,
    }
    for field, value in gp_changes.items():
        gp = replace(GPSettings(), **{field: value})
        assert GPSettings.from_dict(gp.to_dict()) == gp
        assert run_key(replace(spec, config=LearnerConfig(gp=gp)), "fp") != base, field
        assert replace(task, gp=gp.to_dict()).key != task.key, field
    for field, value in {
        "cutoff": "paper",
        "evidence_margin": 0.0,
        "auxiliary": True,
        "transfer": "control",
    }.items():
        config = replace(LearnerConfig(), **{field: value})
        assert LearnerConfig.from_dict(config.to_dict()) == config
        assert run_key(replace(spec, config=config), "fp") != base, field


def test_store_round_trip_and_damaged_files(tmp_path):
    store = RunStore(tmp_path / "runs")
    rows = [
        {
            "step": 0,
            "mean_accuracy": 0.5,
            "uncertainty": float("nan"),
            "action": None,
            "explored": False,
        }
    ]
    assert store.load("k1") is None and "k1" not in store
    store.save("k1", spec(), rows)
    back = store.load("k1")
    assert back[0]["step"] == 0 and math.isnan(back[0]["uncertainty"]) and back[0]["action"] is None
    # The file is strict JSON (a NaN is null there, named apart), which any reader takes.

    def refuse(word: str) -> None:
        raise ValueError(f"not strict JSON: {word}")

    doc = json.loads(store.path("k1").read_text(), parse_constant=refuse)
    assert doc["steps"][0]["uncertainty"] is None and doc["non_finite"] == [
        [0, "uncertainty", "nan"]
    ]
    assert "k1" in store and store.keys() == ["k1"]
    assert not list(
        (tmp_path / "runs").glob("*.tmp")
    )  # written under a temporary name, then renamed
    # A truncated or foreign file is not a result: it is recomputed, never trusted.
    store.path("k2").write_text('{"format": "aptkt.RunResult/1", "key": "k2", "steps": [')
    assert store.load("k2") is None
    store.path("k3").write_text(
        json.dumps({"format": "aptkt.RunResult/1", "key": "other", "steps": []})
    )
    assert store.load("k3") is None
