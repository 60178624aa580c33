"""The variant registry: one place for the paper's variants, open to a user's class by import path."""

from __future__ import annotations

import pytest

from morfic_cli.errors import MorficError, UnknownNameError
from morfic_cli.report import paper
from morfic_cli.rl import variants as V
from morfic_cli.runs import run_name, run_of


def test_the_registry_holds_the_papers_seven_in_table_order():
    assert V.VARIANTS == ("ppo", "actor-only", "concat", "film", "film-scaled", "hyper", "adaln")
    assert V.table_variants("main") == paper.ZERO_SHOT_TRANSFER.columns
    assert V.table_variants("ablation") == paper.CRITIC_CONDITIONING_ABLATION.columns
    assert [V.variant_order(v) for v in V.VARIANTS] == list(range(7))
    assert V.variant_order("my_lab:Critic") == 7
    assert paper.METHOD_LABELS["film-scaled"] == V.STOCK["film-scaled"].label == "MorFiC-F(Scaled)"


def test_run_names_follow_one_rule():
    assert run_name("film", 0, "smoke") == "film-smoke-s0"
    assert run_name("film", 2, "cpu") == "film-cpu-s2"
    assert run_name("my_lab.critics:GatedCritic", 1, "smoke") == "my_lab.critics.GatedCritic-smoke-s1"
    assert run_of("runs/film-s0@3") == run_of("film-s0") == "film-s0"  # names of an earlier morfic still read
    assert run_of("abcdef12", {"run": "ppo-s1"}) == "ppo-s1"


def test_a_user_class_becomes_a_variant_with_the_stock_actor():
    variant = V.resolve_variant("collections:OrderedDict")  # any importable class stands in for a critic here
    assert not variant.stock and variant.label == "OrderedDict"
    actor, critic, groups = variant.model_cfgs()
    assert actor["class_name"] == V.ACTOR_CLASS and actor["morphology_group"] == "morphology"
    assert critic["class_name"] == "collections:OrderedDict"
    assert groups["critic"] == ["critic", "privileged", "morphology"]


@pytest.mark.parametrize(("name", "needle"), [
    ("film-xl", "unknown variant 'film-xl'"),
    ("no_such_module_xyz:Critic", "cannot import module 'no_such_module_xyz'"),
    ("collections:NoSuchClass", "has no 'NoSuchClass'"),
    ("collections:abc", "not a class"),
    (":Critic", "not an import path"),
])
def test_bad_variant_names_are_user_errors(name, needle):
    with pytest.raises(MorficError, match=needle):
        V.resolve_variant(name)


def test_an_unknown_stock_name_lists_the_valid_ones():
    with pytest.raises(UnknownNameError) as info:
        V.resolve_variant("film-xl")
    for name in V.VARIANTS:
        assert name in str(info.value)
