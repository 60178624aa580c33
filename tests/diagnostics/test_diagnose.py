"""`morfic diagnose` and `--fixed-rollout` on smoke checkpoints: rows, stored artifacts, reuse, bad input."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from smoke_runs import DEFAULT_NAME, copy_store

from morfic_cli.diagnostics.samples import DiagnoseCfg, collect_samples, load_samples

# The smallest budget that still has samples in I_eps: --trunc-eps 0.8 -> H_eps = ceil(ln 0.8 / ln 0.99) = 23.
SMALL = ("--envs", "2", "--steps", "30", "--trunc-eps", "0.8")


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def smoke_store(smoke_runs):
    """Smoke-trained film and ppo checkpoints (ppo trained last: the newest run), shared by this module's tests
    (the session's template, copied per test)."""
    return smoke_runs.template((("film", "ppo"), 0, DEFAULT_NAME))


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    return copy_store(smoke_store, tmp_path, monkeypatch)


def test_diagnose_rows_table_figure_and_reuse(run_cli, store):
    code, out, err = run_cli(
        "diagnose", "runs/film-s0", "runs/ppo-s0", "--robots", "go2,aliengo", *SMALL, "--format", "json", "--quiet"
    )
    assert code == 0, err
    rows = json.loads(out)
    assert [(r["run"], r["variant"], r["robot"]) for r in rows] == [
        ("film-s0", "film", "go2"),
        ("film-s0", "film", "aliengo"),
        ("ppo-s0", "ppo", "go2"),
        ("ppo-s0", "ppo", "aliengo"),
    ]
    for r in rows:
        assert {"run", "variant", "robot", "ev", "nvb", "nve", "asa", "flip", "cos_grad"} <= set(r)
        assert r["h_eps"] == 23 and r["gamma"] == 0.99 and r["num_envs"] == 2 and r["steps"] == 30
        assert 0 < r["n_samples"] <= 60 and r["coverage"] == pytest.approx(r["n_samples"] / 60)
        assert r["nve"] >= r["abs_nvb"] == abs(r["nvb"])
        assert r["asa"] + r["flip"] == pytest.approx(1.0)
        assert -1.0 <= r["cos_grad"] <= 1.0 and r["ev"] <= 1.0
        assert r["cell"] == f"{abs(r['nvb']):.3f}/{r['nve']:.3f}/{r['asa']:.3f}"
        assert r["reused"] is False
    assert rows[0]["d"] == 0.0 and rows[1]["d"] > 0

    manifest = store.read_manifest("diagnoses/calibration")
    assert manifest.kind == "diagnosis" and set(manifest.files) == {"calibration.csv", "ev.png", "ev.pdf"}
    assert store.read_file(manifest.id, "ev.png").startswith(b"\x89PNG")
    assert store.read_file(manifest.id, "ev.pdf").startswith(b"%PDF")
    assert manifest.inputs["checkpoint/runs/film-s0"] == store.resolve("runs/film-s0")
    table = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "calibration.csv").decode())))
    assert [float(t["ev"]) for t in table] == pytest.approx([r["ev"] for r in rows])
    rollout = store.read_manifest(rows[0]["rollout"])
    assert rollout.kind == "rollout" and set(rollout.files) == {"rollout.mcap", "obs.npz"}
    assert manifest.inputs["rollout/runs/film-s0/go2"] == rollout.id

    # the same inputs again: the stored rollouts are read back, and the metrics are the same numbers
    code, out, err = run_cli("diagnose", "runs/film-s0", "--robots", "go2", *SMALL, "-f", "json", "-q")
    assert code == 0, err
    (again,) = json.loads(out)
    assert again["reused"] is True and again["rollout"] == rows[0]["rollout"]
    for key in ("ev", "nvb", "nve", "asa", "flip", "cos_grad", "n_samples"):
        assert again[key] == rows[0][key], key
    assert store.read_manifest("diagnoses/calibration").id != manifest.id
    assert len(store.ls("rollout")) == 4
    # another seed is another rollout
    code, out, _ = run_cli("diagnose", "runs/film-s0", "--robots", "go2", *SMALL, "--seed", "1", "-f", "json", "-q")
    assert code == 0 and json.loads(out)[0]["rollout"] != rows[0]["rollout"]


def test_diagnose_table_output(run_cli, store):
    code, out, err = run_cli("diagnose", "runs/film-s0", "--robots", "go1", *SMALL)
    assert code == 0, err
    assert "critic calibration" in out and "go1" in out and "film" in out  # headers shrink to the 80-column console
    assert "stored diagnoses/calibration@1" in err


def test_fixed_rollout_aliengo_with_default_actor_and_critics(run_cli, store):
    code, out, err = run_cli("diagnose", "--fixed-rollout", "aliengo", *SMALL, "--format", "json", "--quiet")
    assert code == 0, err
    rows = json.loads(out)
    # default actor: the newest film run; default critics: the newest run of each variant, in the paper's order
    assert [(r["critic"], r["variant"]) for r in rows] == [("MC", "mc"), ("ppo-s0", "ppo"), ("film-s0", "film")]
    mc = rows[0]
    assert mc["flip"] == 0.0 and mc["cos_grad"] == pytest.approx(1.0) and mc["asa"] == 1.0
    for r in rows:
        assert {"critic", "variant", "robot", "flip", "cos_grad"} <= set(r)
        assert r["robot"] == "aliengo" and r["actor"] == "film-s0" and r["rollout"] == mc["rollout"]
        assert r["asa"] + r["flip"] == pytest.approx(1.0)
    manifest = store.read_manifest("diagnoses/fixed-rollout/aliengo")
    assert manifest.inputs["actor"] == store.resolve("runs/film-s0")
    assert manifest.inputs["rollout"] == mc["rollout"]
    assert {"critic/runs/ppo-s0", "critic/runs/film-s0"} <= set(manifest.inputs)
    table = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "fixed_rollout.csv").decode())))
    assert [t["critic"] for t in table] == ["MC", "ppo-s0", "film-s0"]

    # the film critic on its own actor's rollout is exactly the calibration of film-s0 on aliengo (same samples)
    code, out, _ = run_cli("diagnose", "runs/film-s0", "--robots", "aliengo", *SMALL, "-f", "json", "-q")
    (cal,) = json.loads(out)
    assert cal["rollout"] == mc["rollout"] and cal["reused"] is True
    for key in ("flip", "cos_grad", "ev", "nvb", "nve"):
        assert cal[key] == pytest.approx(rows[2][key]), key


def test_fixed_rollout_with_explicit_actor_and_critics(run_cli, store):
    code, out, err = run_cli(
        "diagnose",
        "--fixed-rollout",
        "go1",
        "--actor",
        "runs/ppo-s0",
        "--critics",
        "runs/film-s0",
        *SMALL,
        "-f",
        "csv",
        "-q",
    )
    assert code == 0, err
    table = list(csv.DictReader(io.StringIO(out)))
    assert [(t["critic"], t["actor"]) for t in table] == [("MC", "ppo-s0"), ("film-s0", "ppo-s0")]
    code, out, err = run_cli(
        "diagnose", "--fixed-rollout", "go1", "--actor", "runs/ppo-s0", "--critics", "runs/film-s0", *SMALL
    )
    assert code == 0, err
    assert "Flip" in out and "Cos." in out and "rollout reused" in err


def test_stored_samples_read_back_exactly(store):
    from morfic_cli.rl.load import load_trained

    trained = load_trained(store, "runs/film-s0")
    cfg = DiagnoseCfg(robots=("a1",), num_envs=2, steps=12, seed=4)
    fresh = collect_samples(store, trained, "a1", cfg)
    back = load_samples(store, fresh.rollout_id)
    assert not fresh.reused and back.reused and back.robot == "a1"
    for key in ("action", "reward", "value", "done", "time_out"):
        np.testing.assert_array_equal(getattr(back, key), getattr(fresh, key))
    for group, a in fresh.obs.items():
        np.testing.assert_array_equal(back.obs[group], a)
    assert collect_samples(store, trained, "a1", cfg).rollout_id == fresh.rollout_id


def test_incompatible_critics_are_refused():
    from morfic_cli.diagnostics.fixed_rollout import check_compatible
    from morfic_cli.errors import MorficError
    from morfic_cli.rl.config import smoke_preset

    cfg = smoke_preset("film")
    actor = SimpleNamespace(cfg=cfg)
    check_compatible(actor, SimpleNamespace(cfg=smoke_preset("ppo")), "runs/ppo-s0")  # other variant: fine
    other = dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, gamma=0.95))
    with pytest.raises(MorficError, match="ppo.gamma"):
        check_compatible(actor, SimpleNamespace(cfg=other), "runs/x")
    obs = dataclasses.replace(cfg.env, obs=dataclasses.replace(cfg.env.obs, history_len=5))
    with pytest.raises(MorficError, match="env.obs"):
        check_compatible(actor, SimpleNamespace(cfg=dataclasses.replace(cfg, env=obs)), "runs/y")


def test_default_critics_leave_out_an_incompatible_run_and_say_why(monkeypatch, tmp_path):
    """Named, an incompatible critic is an error; chosen by default (the newest run of each variant), it is left out
    with its reason, and no compatible critic at all is an error."""
    from morfic_cli.diagnostics import fixed_rollout as F
    from morfic_cli.errors import MorficError
    from morfic_cli.rl import load
    from morfic_cli.rl.config import smoke_preset
    from morfic_cli.store import Store

    cfg = smoke_preset("film")
    act = dataclasses.replace(cfg.env, obs=dataclasses.replace(cfg.env.obs, extended_morphology=True))
    cfgs = {"runs/film-s0": cfg, "runs/ppo-s0": smoke_preset("ppo"), "runs/act-s0": dataclasses.replace(cfg, env=act)}
    monkeypatch.setattr(load, "load_trained", lambda store, spec: SimpleNamespace(cfg=cfgs[spec]))
    monkeypatch.setattr(F, "default_critics", lambda store, on_skip=None: list(cfgs))
    diag = DiagnoseCfg(num_envs=2, steps=30, trunc_eps=0.8)
    skipped: list[tuple[str, str]] = []
    store = Store(tmp_path / "s")
    models = F.load_models(store, "runs/film-s0", None, diag, on_skip=lambda r, w: skipped.append((r, w)))
    assert models.critic_specs == ["runs/film-s0", "runs/ppo-s0"]
    assert skipped == [("runs/act-s0", "trained with other env.obs than the actor")]
    with pytest.raises(MorficError, match="env.obs"):
        F.load_models(store, "runs/film-s0", ["runs/act-s0"], diag)
    monkeypatch.setattr(F, "default_critics", lambda store, on_skip=None: ["runs/act-s0"])
    with pytest.raises(MorficError, match="--critics"):
        F.load_models(store, "runs/film-s0", None, diag)


def test_ev_figure_handles_nan_and_very_negative_ev():
    from morfic_cli.diagnostics.figures import ev_figure

    rows = [
        {"run": "a", "variant": "film", "robot": "go2", "ev": 0.8},
        {"run": "a", "variant": "film", "robot": "b1", "ev": -12.0},
        {"run": "b", "variant": "ppo", "robot": "go2", "ev": math.nan},
    ]
    png, pdf = ev_figure(rows)
    assert png.startswith(b"\x89PNG") and pdf.startswith(b"%PDF")


@pytest.mark.parametrize("runs", [1, 3, 7])
def test_ev_value_labels_do_not_overlap(runs):
    """Seven variants on seven robots (the shipped report): each bar's value label stays clear of the others'."""
    import matplotlib.pyplot as plt

    from morfic_cli.diagnostics.figures import ev_plot

    robots = ["go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c"]
    rows = [
        {"run": f"r{k}", "variant": "film", "robot": robot, "ev": -0.55 if j % 2 else -25.0 - k}
        for k in range(runs)
        for j, robot in enumerate(robots)
    ]
    fig = ev_plot(rows)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in fig.axes[0].texts]
    plt.close(fig)
    assert len(boxes) == runs * len(robots)
    overlaps = [(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1 :] if a.overlaps(b)]
    assert not overlaps, overlaps[:3]  # horizontal labels of 7 runs overlapped ("-0.550.55")


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        ([], "name the runs"),
        (["--actor", "runs/film-s0"], "belong to --fixed-rollout"),
        (["runs/film-s0", "--fixed-rollout", "aliengo"], "--critics"),
        (["runs/film-s0", "runs/film-s0"], "named twice"),
        (["runs/film-s0", "--robots", "go7"], "unknown robot 'go7'"),
        (["runs/film-s0", "--mode", "bogus"], "'bogus' is not one of 'descriptor', 'full'"),
        (["runs/film-s0", "--envs", "0"], "Invalid value for '--envs'"),
        (["runs/film-s0", "--steps", "100", "--trunc-eps", "0.05"], "--steps 100 is too short"),
        (["runs/film-s0", "--trunc-eps", "1.5"], "--trunc-eps must be in (0, 1)"),
        (["runs/nope"], "no artifact 'runs/nope'"),
        (["tables/none", "--robots", "go2"], "no artifact"),
        (["--fixed-rollout", "go1,a1"], "takes one robot"),
        (["--fixed-rollout", "aliengo", "--critics", "runs/film-s0,runs/film-s0"], "twice"),
        (["--fixed-rollout", "aliengo", "--critics", ","], "--critics is empty"),
        (["--fixed-rollout", "aliengo", "--actor", "runs/nope"], "no artifact 'runs/nope'"),
    ],
)
def test_bad_input_is_an_error_and_writes_nothing(run_cli, store, argv, needle):
    before = {r["id"] for r in store.ls()}
    code, out, err = run_cli("diagnose", *SMALL, *argv)  # later flags win
    assert code == 1
    assert err.startswith("Error: ") and needle in err, err
    assert out == "" and "Traceback" not in err
    assert {r["id"] for r in store.ls()} == before


def test_fixed_rollout_without_a_film_run_says_what_to_do(run_cli, tmp_path, monkeypatch):
    monkeypatch.setenv("MORFIC_STORE", str(tmp_path / "empty"))
    code, out, err = run_cli("diagnose", "--fixed-rollout", "aliengo", *SMALL)
    assert code == 1 and err.startswith("Error: ") and "--actor" in err and "morfic train" in err
