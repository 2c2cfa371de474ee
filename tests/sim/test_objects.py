"""The object library: the paper's objects, their relations, and clear errors for bad files."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from aptkt.errors import ConfigError
from aptkt.sim.objects import default_library, load_library

GOOD = """
schema_version = 1
[[object]]
name = "my_block"
description = "a foam block of mine"
related = ["rough_sponge"]
  [[object.layer]]
  thickness = 0.02
  modulus = 2e4
  conductivity = 0.04
  heat_capacity = 5e4
  [object.surface]
  friction_static = 0.9
  friction_kinetic = 0.7
  roughness_rms = 1e-5
  contact_conductance = 1500
"""


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "objects.toml"
    p.write_text(textwrap.dedent(text))
    return p


def test_paper_objects_and_relations():
    lib = default_library()
    priors, new = lib.with_role("prior"), lib.with_role("new")
    assert len(priors) == 10 and len(new) == 5
    assert sorted(lib[o].index for o in priors) == list(range(1, 11))
    assert sorted(lib[o].index for o in new) == list(range(11, 16))
    for name in new:  # paper §5.1: each new object has one or more related priors
        assert lib[name].related and all(lib[r].role == "prior" for r in lib[name].related)
    # the examples the paper names
    assert "rough_sponge" in lib["smooth_sponge"].related
    assert "paper_box" in lib["hard_box"].related
    assert "metal_toolbox" in lib["biscuit_box"].related


def test_user_file_adds_objects_with_next_index(tmp_path):
    lib = load_library(write(tmp_path, GOOD))
    assert len(lib) == 16 and lib["my_block"].index == 16 and lib["my_block"].role == "custom"
    assert lib["my_block"].source.endswith("objects.toml")
    alone = load_library(
        write(tmp_path, GOOD.replace('related = ["rough_sponge"]', "")), include_default=False
    )
    assert list(alone) == ["my_block"] and alone["my_block"].index == 1


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("modulus = 2e4", "modulus = -2e4", "layer[0].modulus"),
        ("modulus = 2e4", "", "layer[0].modulus"),
        ("modulus = 2e4", 'modulus = "soft"', "layer[0].modulus"),
        ("friction_static = 0.9", "friction_static = 0.5", "surface.friction_static"),
        (
            "roughness_rms = 1e-5",
            "roughness_rms = 1e-5\n  roughnes_band = [1e-4, 1e-3]",
            "surface.roughnes_band",
        ),
        ('related = ["rough_sponge"]', 'related = ["no_such_thing"]', "related"),
        ('name = "my_block"', 'name = "My Block"', "name"),
        ("thickness = 0.02", "thickness = 2.0", "layer"),
    ],
)
def test_bad_fields_name_object_and_field(tmp_path, old, new, field):
    assert old in GOOD
    with pytest.raises(ConfigError) as err:
        load_library(write(tmp_path, GOOD.replace(old, new)))
    msg = str(err.value)
    assert "objects.toml" in msg and field in msg
    if "name = " not in old:
        assert "my_block" in msg


def test_duplicates_and_broken_toml(tmp_path):
    with pytest.raises(ConfigError, match="defined twice"):
        load_library(write(tmp_path, GOOD.replace("my_block", "towel")))
    with pytest.raises(ConfigError, match="index"):
        load_library(
            write(tmp_path, GOOD.replace('name = "my_block"', 'name = "my_block"\nindex = 3'))
        )
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_library(write(tmp_path, "[[object]\nname = 1"))
    with pytest.raises(ConfigError, match="not found"):
        load_library(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="schema_version"):
        load_library(write(tmp_path, GOOD.replace("schema_version = 1", "schema_version = 9")))


RELATION = """
  [[object.relation]]
  prior = "rough_sponge"
  modality = "force"
  actions = ["P1", "P2"]
  why = "soft foam"
"""


def test_relations_name_prior_modality_and_actions(tmp_path):
    lib = load_library(write(tmp_path, GOOD.replace('related = ["rough_sponge"]', "") + RELATION))
    (rel,) = lib["my_block"].relations
    assert (rel.prior, rel.modality, rel.actions, rel.why) == (
        "rough_sponge",
        "force",
        ("P1", "P2"),
        "soft foam",
    )
    assert lib["my_block"].related == ("rough_sponge",)  # a relation makes the prior related
    for old, new, field in [
        ('actions = ["P1", "P2"]', "actions = []", "relation[0].actions"),
        ('prior = "rough_sponge"', "", "relation[0].prior"),
        ('why = "soft foam"', 'why = "soft foam"\n  wy = 1', "relation[0].wy"),
    ]:
        with pytest.raises(ConfigError, match=field.replace("[", r"\[").replace("]", r"\]")):
            load_library(write(tmp_path, GOOD + RELATION.replace(old, new)))
    with pytest.raises(ConfigError, match="unknown object 'no_such_prior'"):
        load_library(write(tmp_path, GOOD + RELATION.replace("rough_sponge", "no_such_prior")))
