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


def test_settings_added_later_leave_stored_keys_as_they_were():
    """Keys computed by aptkt 0.1.0 before warm_start, class_prior, latent_mean, the
    modality-weight prior and the optimiser's tolerance existed, when the learner searched from two starts (commit 1fed19f):
    a store or prior file from then must still be found, or a resumed run recomputes it all.
    Those runs had flat modality weights, the "training" class posterior and a random restart,
    so their keys belong to those settings; the new defaults must get keys of their own, or a
    resumed store would hand out results computed the old way."""
    flat = GPSettings(
        n_restarts=1,
        modality_weight_prior=False,
        class_prior="training",
        latent_mean="zero",
        optimizer_tol=DEFAULTS.optimizer_tol,
        prior_feature_scale="spread",
    )
    spec = RunSpec(
        method="APTKT",
        config=LearnerConfig(gp=flat),
        data="/d/a.h5",
        actions=("P1", "S1"),
        new_objects=("a", "b"),
        pool_trials=(0, 1),
        test_trials=(2, 3),
        prior="/p/prior-3-abc.npz",
        pool_seed=5,
    )
    assert run_key(spec, "fp") == "8e960c17a32b727790d4f47b"
    task = PriorTask(
        fingerprint="fp",
        data="/d/a.h5",
        objects=("x", "y", "z"),
        actions=("P1",),
        trials=(0, 1, 2),
        seed=3,
        directory="/p",
        gp={
            "n_restarts": 1,
            "modality_weight_prior": False,
            "class_prior": "training",
            "latent_mean": "zero",
            "optimizer_tol": DEFAULTS.optimizer_tol,
            "prior_feature_scale": "spread",
        },
    )
    assert task.key == "4596257baaf0144904e0"
    default = replace(spec, config=LearnerConfig())
    assert run_key(default, "fp") != run_key(spec, "fp")
    assert replace(task, gp=None).key != task.key
    # Each later setting is part of both keys.
    uniform = replace(flat, class_prior="uniform")
    assert run_key(replace(spec, config=LearnerConfig(gp=uniform)), "fp") != run_key(spec, "fp")
    assert (
        replace(task, gp={"class_prior": "uniform", "modality_weight_prior": False}).key != task.key
    )
    one_start = replace(flat, n_restarts=0)
    assert run_key(replace(spec, config=LearnerConfig(gp=one_start)), "fp") != run_key(spec, "fp")
    base_rate = replace(flat, latent_mean="base-rate")
    assert run_key(replace(spec, config=LearnerConfig(gp=base_rate)), "fp") != run_key(spec, "fp")
    assert base_rate.to_dict()["latent_mean"] == "base-rate"
    loose = replace(flat, optimizer_tol=1e-6)
    assert run_key(replace(spec, config=LearnerConfig(gp=loose)), "fp") != run_key(spec, "fp")
    assert replace(task, gp={**task.gp, "optimizer_tol": 1e-6}).key != task.key
    assert GPSettings.from_dict(loose.to_dict()) == loose
    noise = replace(flat, prior_feature_scale="noise")  # the default since it was added
    assert run_key(replace(spec, config=LearnerConfig(gp=noise)), "fp") != run_key(spec, "fp")
    assert replace(task, gp={**task.gp, "prior_feature_scale": "noise"}).key != task.key
    assert GPSettings.from_dict(noise.to_dict()) == noise
    assert "prior_feature_scale" not in flat.to_dict()


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
