"""A library that grows: ``aptkt prior merge`` and :func:`merge_priors` — refitted on the merged
observations, provenance kept, and libraries that do not fit together refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aptkt.cli import main
from aptkt.errors import IncompatiblePriorsError
from aptkt.learning import GPSettings, PriorKnowledge
from aptkt.learning.library import merge_priors
from aptkt.learning.observations import Observations


def _obs(objects, n=8, seed=0, action="A", dims=(2, 3), offset=0.0):
    rng = np.random.default_rng(seed)
    names = np.repeat(objects, n)
    centre = {o: rng.normal(scale=5.0, size=sum(dims)) + offset for o in objects}
    X = np.array([centre[o] for o in names]) + rng.normal(size=(names.size, sum(dims)))
    mods = {"m0": X[:, : dims[0]], "m1": X[:, dims[0] :]}
    return Observations(action, mods, names, np.tile(np.arange(n), len(objects)))


def _prior(objects, seed=0, **kw):
    gp = kw.pop("gp", None)
    return PriorKnowledge.build({"A": _obs(objects, seed=seed, **kw)}, gp=gp, seed=0)


def test_a_merged_library_is_the_library_built_on_all_the_observations():
    a, b = _prior(["o1", "o2", "o3"], seed=1), _prior(["n1", "n2"], seed=2)
    merged = merge_priors([("a.npz", a), ("b.npz", b)])
    assert merged.objects == ["n1", "n2", "o1", "o2", "o3"]
    together = Observations.concat([a["A"].observations, b["A"].observations])
    direct = PriorKnowledge.build({"A": together}, gp=a.gp_settings, seed=0)
    X = together.modalities
    # The metric and the model are refitted on all observations, as one build would.
    np.testing.assert_allclose(
        merged["A"].pipeline.transform(together)[0], direct["A"].pipeline.transform(together)[0]
    )
    np.testing.assert_allclose(merged["A"].model.theta_, direct["A"].model.theta_)
    assert X["m0"].shape[0] == len(merged["A"].observations)
    provenance = merged.metadata["provenance"]
    assert [p["source"] for p in provenance] == ["a.npz", "b.npz"]
    assert provenance[1]["objects"] == ["n1", "n2"]
    assert provenance[0]["trials"]["A"]["o1"] == list(range(8))
    # A library merged again keeps every object's origin.
    c = _prior(["z1", "z2"], seed=3)
    again = merge_priors([("ab.npz", merged), ("c.npz", c)])
    assert [p["source"] for p in again.metadata["provenance"]] == ["a.npz", "b.npz", "c.npz"]


@pytest.mark.parametrize(
    "other, fragment",
    [
        (lambda: _prior(["n1", "n2"], seed=2, dims=(2, 4)), "other feature columns"),
        (lambda: PriorKnowledge.build({"B": _obs(["n1", "n2"], action="B")}), "other actions"),
        (
            lambda: _prior(["n1", "n2"], seed=2, gp=GPSettings(prior_feature_scale="spread")),
            "another metric",
        ),
        (lambda: _prior(["o2", "n2"], seed=2), "both hold an object named 'o2'"),
    ],
)
def test_libraries_that_do_not_fit_together_are_refused_naming_why(other, fragment):
    a = _prior(["o1", "o2", "o3"], seed=1)
    with pytest.raises(IncompatiblePriorsError, match=fragment):
        merge_priors([("a.npz", a), ("b.npz", other())])


def test_other_extraction_settings_or_movements_are_refused():
    a, b = _prior(["o1", "o2"], seed=1), _prior(["n1", "n2"], seed=2)
    a.metadata["extraction"] = {"thermal_bin": 0.1}
    b.metadata["extraction"] = {"thermal_bin": 0.2}
    with pytest.raises(IncompatiblePriorsError, match="thermal_bin: 0.2 against 0.1"):
        merge_priors([("a.npz", a), ("b.npz", b)])
    b.metadata["extraction"] = {"thermal_bin": 0.1}
    a.metadata["action_definitions"] = {"A": {"depth": 1.0}}
    b.metadata["action_definitions"] = {"A": {"depth": 2.0}}
    with pytest.raises(IncompatiblePriorsError, match="another movement"):
        merge_priors([("a.npz", a), ("b.npz", b)])


def test_prior_merge_on_the_command_line(tmp_path, capsys):
    a = _prior(["o1", "o2", "o3"], seed=1).save(tmp_path / "a.npz")
    b = _prior(["n1", "n2"], seed=2).save(tmp_path / "b.npz")
    out = tmp_path / "lib.npz"
    assert main(["prior", "merge", str(a), str(b), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "a library of 5 objects" in said
    merged = PriorKnowledge.load(out)
    assert len(merged.objects) == 5
    digests = [p["sha256"] for p in merged.metadata["provenance"]]
    assert len(digests) == 2 and all(len(d) == 64 for d in digests)
    assert main(["prior", "inspect", str(out), "--json"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["metadata"]["merged_from"] == [str(a), str(b)]
    # Mistakes: one line each, nothing written.
    bad = _prior(["n1", "n9"], seed=2, dims=(1, 4)).save(tmp_path / "bad.npz")
    for argv, fragment in (
        (["prior", "merge", str(a), str(b), "-o", str(out)], "exists (give --force"),
        (["prior", "merge", str(a), "-o", str(tmp_path / "x.npz")], "at least two"),
        (["prior", "merge", str(a), str(a), "-o", str(tmp_path / "x.npz")], "more than once"),
        (["prior", "merge", str(a), str(bad), "-o", str(tmp_path / "x.npz")], "feature columns"),
        (
            ["prior", "merge", str(a), str(tmp_path / "no.npz"), "-o", str(tmp_path / "x.npz")],
            "no.npz",
        ),
    ):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("aptkt prior: error:") or err.startswith(
            "aptkt prior merge: error:"
        ), err
        assert err.count("\n") == 0 and fragment in err, err
    assert not (tmp_path / "x.npz").exists()


def test_this_skins_features_and_another_sensors_are_not_merged():
    """A library of a table holding another sensor's features (z-scored) and one of this skin's
    (log of the texture's activities) measure in different spaces."""
    from aptkt.learning.pipeline import GENERIC_TRANSFORMS, SKIN_TRANSFORMS

    def built(objects, seed, transforms):
        obs = _obs(objects, seed=seed, dims=(3, 2))
        obs.modalities = {
            "texture": np.abs(obs.modalities["m0"]) + 1,
            "force": obs.modalities["m1"],
        }
        return PriorKnowledge.build({"A": obs}, seed=0, transforms=transforms)

    skin = built(["o1", "o2"], 1, SKIN_TRANSFORMS)
    other = built(["n1", "n2"], 2, GENERIC_TRANSFORMS)
    with pytest.raises(
        IncompatiblePriorsError,
        match=r"action A's features are transformed otherwise \(z-scored only against "
        r"texture: log of columns 0,1,2\)",
    ):
        merge_priors([("skin.npz", skin), ("other.npz", other)])
    # Modalities that neither transforms beyond z-scoring do not keep libraries apart.
    merge_priors([("a.npz", _prior(["o1", "o2"], seed=1)), ("b.npz", _prior(["n1", "n2"], seed=2))])
    merge_priors([("skin.npz", skin), ("skin2.npz", built(["n1", "n2"], 2, SKIN_TRANSFORMS))])
