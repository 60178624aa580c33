"""The variant registry: one place for the paper's variants, open to a user's class by import path."""

from __future__ import annotations

import pytest

from morfic_cli.errors import MorficError, UnknownNameError
from morfic_cli.report import paper
from morfic_cli.rl import variants as V
from morfic_cli.runs import run_name, run_of


def test_the_registry_holds_the_papers_seven_in_table_order():
    assert V.VARIANTS[:7] == ("ppo", "actor-only", "concat", "film", "film-scaled", "hyper", "adaln")
    n_ext = len(V.table_variants("external"))
    assert set(V.VARIANTS[7 : 7 + n_ext]) == set(V.table_variants("external"))  # then the external baselines
    actuation = ("film-act", "ppo-act", "film-act-wide", "film-act-11d", "film-act-template", "film-act-light")
    assert V.VARIANTS[7 + n_ext :] == V.table_variants("actuation") == actuation  # then issue 58's, the ablations last
    assert not set(V.table_variants("actuation")) & set(V.REPRODUCE_VARIANTS)  # trained by name only
    assert V.table_variants("main") == paper.ZERO_SHOT_TRANSFER.columns
    assert V.table_variants("ablation") == paper.CRITIC_CONDITIONING_ABLATION.columns
    assert [V.variant_order(v) for v in V.VARIANTS] == list(range(len(V.VARIANTS)))
    assert V.variant_order("my_lab:Critic") == len(V.VARIANTS)
    assert paper.METHOD_LABELS["film-scaled"] == V.STOCK["film-scaled"].label == "MorFiC-F(Scaled)"


@pytest.mark.parametrize(
    ("name", "label", "key", "film_act", "value"),
    [
        ("film-act-wide", "MorFiC-F(act)-wide", "env.rand.actuation.curriculum", True, False),
        ("film-act-11d", "MorFiC-F(act)-11D", "env.obs.extended_morphology", True, False),
        ("film-act-template", "MorFiC-F(act)-template", "env.rand.geometry.enabled", True, False),
        ("film-act-light", "MorFiC-F(act)-light", "env.rand.actuation.mass_scale", [0.8, 4.0], [0.8, 1.0]),
    ],
)
def test_each_ablation_is_film_act_with_one_env_key_switched_off(name, label, key, film_act, value):
    """The smoke trainings of every variant leave the ablations out: film-act's networks and env code, this one key."""
    from morfic_cli.rl.config import preset_cfg, train_cfg_to_dict
    from morfic_cli.validation import flatten

    base = flatten(train_cfg_to_dict(preset_cfg("cpu", "film-act", 0)))
    ablation = flatten(train_cfg_to_dict(preset_cfg("cpu", name, 0)))
    differ = {k: (base[k], ablation[k]) for k in base if base[k] != ablation[k]}
    assert differ == {"variant": ("film-act", name), key: (film_act, value)}
    assert V.STOCK[name].label == label and V.STOCK[name].tables == ("actuation",)
    assert V.model_cfgs(name) == V.model_cfgs("film-act")
    assert V.eval_modes(name) == V.eval_modes(name, trained_regime=True) == ("descriptor", "full", "actuation-matched")
    assert V.STOCK["film-act"].env_overrides == V.ACTUATION_ENV  # the ablations did not change film-act's env


def test_a_run_is_evaluated_in_its_tables_modes():
    both = ("descriptor", "full")
    assert [V.eval_modes(v) for v in ("ppo", "film", "film-scaled", "genloco", "my_lab:Critic")] == [both] * 5
    assert [V.eval_modes(v, trained_regime=True) for v in ("ppo", "film", "adaln", "my_lab:Critic")] == [
        ("descriptor",)
    ] * 4  # the seed-0 runs' eval-1.0 configs
    assert [V.eval_modes(v, trained_regime=True) for v in ("bot", "urma", "genloco")] == [both] * 3  # issue 57
    assert V.eval_modes("ppo-act", trained_regime=True) == ("descriptor", "full", "actuation-matched")


def test_run_names_follow_one_rule():
    assert run_name("film", 0, "smoke") == "film-smoke-s0"
    assert run_name("film", 2, "cpu") == "film-cpu-s2"
    assert run_name("my_lab.critics:GatedCritic", 1, "smoke") == "my_lab.critics.GatedCritic-smoke-s1"
    assert run_of("runs/film-s0@3") == run_of("film-s0") == "film-s0"  # names of an earlier morfic still read
    assert run_of("abcdef12", {"run": "ppo-s1"}) == "ppo-s1"


def test_a_user_class_becomes_a_variant_with_the_stock_actor():
    with V.consent_scope(["morfic_cli.rl.models:MorficCritic"]):  # morfic's own critic class, named by import path
        variant = V.resolve_variant("morfic_cli.rl.models:MorficCritic")
    assert not variant.stock and variant.label == "MorficCritic"
    actor, critic, groups = variant.model_cfgs()
    assert actor["class_name"] == V.ACTOR_CLASS and actor["morphology_group"] == "morphology"
    assert critic["class_name"] == "morfic_cli.rl.models:MorficCritic"
    assert groups["critic"] == ["critic", "privileged", "morphology"]


@pytest.mark.parametrize(
    ("name", "needle"),
    [
        ("film-xl", "unknown variant 'film-xl'"),
        ("no_such_module_xyz:Critic", "cannot import module 'no_such_module_xyz'"),
        ("collections:NoSuchClass", "has no 'NoSuchClass'"),
        ("collections:abc", "not a class"),
        ("collections:OrderedDict", "class OrderedDict is not a critic model: a torch.nn.Module subclass"),  # issue 53
        ("torch.nn:Linear", "class Linear is not a critic model"),
        (":Critic", "not an import path"),
    ],
)
def test_bad_variant_names_are_user_errors(name, needle):
    with V.consent_scope([name] if ":" in name[1:] else []), pytest.raises(MorficError, match=needle):
        V.resolve_variant(name)


def test_an_unknown_stock_name_lists_the_valid_ones():
    with pytest.raises(UnknownNameError) as info:
        V.resolve_variant("film-xl")
    for name in V.VARIANTS:
        assert name in str(info.value)


# ---------------------------------------------------------------------------- consent (issue 36)
@pytest.fixture
def sentinel(tmp_path, monkeypatch):
    """A module on sys.path whose top-level code leaves a marker file when it is imported: (name, marker)."""
    marker = tmp_path / "imported"
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / "sentinel_critic.py").write_text(
        f"import pathlib\npathlib.Path({str(marker)!r}).write_text('imported')\n"
        "from morfic_cli.rl.models import MorficCritic\nclass Critic(MorficCritic):\n    pass\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    monkeypatch.delitem(__import__("sys").modules, "sentinel_critic", raising=False)
    return "sentinel_critic:Critic", marker


def _imported(marker) -> bool:
    import sys

    return marker.exists() or "sentinel_critic" in sys.modules


def test_a_user_variant_is_imported_only_with_consent(sentinel):
    name, marker = sentinel
    with V.consent_scope(), pytest.raises(V.UntrustedVariantError) as info:
        V.resolve_variant(name, source="runs/x")
    assert str(info.value).startswith(
        f"run runs/x needs the user variant {name}; morfic will not import code named "
        f"by a stored run without --trust-variant {name}"
    )
    assert f"morfic trust {name}" in str(info.value)
    assert not _imported(marker)
    with V.consent_scope([name]):
        assert V.resolve_variant(name, source="runs/x").critic_class == name
    assert _imported(marker)


def test_the_allow_list_is_consent_and_lives_in_the_config_folder(sentinel, tmp_path, monkeypatch):
    name, marker = sentinel
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert V.allow_list_path() == tmp_path / "xdg" / "morfic" / "trusted-variants"
    assert V.add_to_allow_list([name, "film", name]) == [name]  # stock names need no trust, each name once
    assert V.add_to_allow_list([name]) == []
    with V.consent_scope():
        assert V.is_trusted(name) and V.trusted_variants() == [name]
        V.resolve_variant(name)
    assert _imported(marker)
    assert V.remove_from_allow_list([name, "other:X"]) == [name]
    with V.consent_scope():
        assert not V.is_trusted(name)
        with pytest.raises(V.UntrustedVariantError):
            V.resolve_variant(name)
    monkeypatch.setenv("XDG_CONFIG_HOME", "relative/path")  # not absolute: ignored (XDG), ~/.config instead
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert V.allow_list_path() == tmp_path / "home" / ".config" / "morfic" / "trusted-variants"


def test_consent_ends_with_its_scope_and_stock_names_need_none():
    with V.consent_scope(["a.b:C"]):
        assert V.is_trusted("a.b:C")
        with V.consent_scope():
            assert not V.is_trusted("a.b:C")
        assert V.is_trusted("a.b:C")
    assert not V.is_trusted("a.b:C")
    with V.consent_scope():
        assert all(V.is_trusted(v) and V.resolve_variant(v, source="runs/x").stock for v in V.VARIANTS)


@pytest.mark.parametrize(
    "name",
    [
        ".relative:Critic",
        "..up:Critic",
        "pkg..mod:Critic",
        "pkg.:Critic",
        "pkg:",
        ":Critic",
        "pkg:Critic.",
        "pkg:Cri tic",
        " pkg:Critic",
        "pkg:Critic\n",
        "pkg/mod:Critic",
        "pkg:Critic:X",
        "os;rm:X",
        "pkg:Critïc",
        "class:X",
        "a" * 190 + ".b:" + "C" * 10,
        "-film",
        "film xl",
        "",
        "x\x1b[31m",
        3,
        None,
        ["film"],
    ],
)
def test_malformed_names_are_refused_before_any_import(name):
    with pytest.raises(MorficError) as info:
        V.check_variant_name(name)
    assert "\x1b" not in str(info.value) and "\n" not in str(info.value)
    with V.consent_scope(), pytest.raises(MorficError):
        V.resolve_variant(name, source="runs/x")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "name", [*V.VARIANTS, "gated", "my-lab.gated_v2", "pkg.mod:Critic", "_p.m2:Outer.Inner", "a" * 180 + ":C"]
)
def test_well_formed_names_pass(name):
    assert V.check_variant_name(name) == name


def test_stored_variants_lists_config_and_meta_names_checked():
    assert V.stored_variants({"variant": "film"}, {"variant": "film", "variants": ["ppo", "a:B"]}) == [
        "film",
        "ppo",
        "a:B",
    ]
    assert V.stored_variants({}, {}) == []
    with pytest.raises(MorficError, match="not an import path"):
        V.stored_variants({"variant": "film"}, {"variant": ".x:Y"})
    with pytest.raises(MorficError, match="not a list"):
        V.stored_variants({"variants": "film"}, {})
