"""`morfic critic-study`: fits from scratch on a frozen actor's data, scored per robot; verdicts from intervals."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
import torch
from smoke_runs import copy_store, train_smoke_runs

from morfic_cli.diagnostics import critic_study as cs
from morfic_cli.diagnostics import study_summary as ss
from morfic_cli.diagnostics.samples import DiagnoseCfg, Samples
from morfic_cli.report import stats
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")

# --trunc-eps 0.8 -> H_eps = ceil(ln 0.8 / ln 0.99) = 23, so 30 steps leave the window t <= 7.
TINY = ("--train-envs", "4", "--held-out", "1", "--target-envs", "2", "--steps", "30", "--trunc-eps", "0.8",
        "--epochs", "1", "--minibatch", "8", "--stride", "2", "--seeds", "2", "--robots", "go2,aliengo",
        "--command-vx", "1.0")


@pytest.fixture(scope="module")
def smoke_store(tmp_path_factory):
    root = tmp_path_factory.mktemp("study") / "store"
    train_smoke_runs(root, ("film",), name="{variant}-smoke-s{seed}")  # reproduce's fixed-rollout actor
    return root


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    return copy_store(smoke_store, tmp_path, monkeypatch)


def test_study_rows_files_and_verdicts(run_cli, store, tmp_path):
    out = tmp_path / "out"
    code, stdout, stderr = run_cli("critic-study", *TINY, "--variants", "film,actor-only,concat", "--out", str(out),
                                   "--format", "json")
    assert code == 0, stderr
    rows = json.loads(stdout)
    # 1 command x (train + 2 robots) x 3 critics (actor-only folded into ppo) = 9 cells, each over 2 fits
    assert len(rows) == 9
    assert {r["variant"] for r in rows} == {"film", "ppo", "concat"}
    assert {r["robot"] for r in rows} == {"train", "go2", "aliengo"}
    assert all(r["n"] == 2 for r in rows)
    manifest = store.read_manifest("diagnoses/critic-study")
    assert set(manifest.files) == {"critic_study.csv", "summary.csv", "verdicts.csv", "fits.csv", "critic_study.png"}
    assert set(manifest.inputs) == {"actor", "rollout/1/train", "rollout/1/go2", "rollout/1/aliengo"}
    study = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "critic_study.csv").decode())))
    assert len(study) == 3 * 3 * 2
    # the train rows are the held-out env: 1 env x window t <= 7 = 8 samples; a target robot has 2 envs x 8
    assert {int(r["n_samples"]) for r in study if r["robot"] == "train"} == {8}
    assert {int(r["n_samples"]) for r in study if r["robot"] == "go2"} == {16}
    fits = list(csv.DictReader(io.StringIO(store.read_file(manifest.id, "fits.csv").decode())))
    # fit set: 3 envs x steps {0, 2, 4, 6} of the window = 12 samples; 1 epoch each
    assert {int(r["n_train"]) for r in fits} == {12}
    assert len(fits) == 3 * 2
    assert (out / "verdicts.csv").exists() and (out / "critic_study.png").read_bytes()[:4] == b"\x89PNG"
    assert "claim (a) at 1 m/s" in stderr and "claim (c) at 1 m/s" in stderr
    # a second call reuses the stored rollouts: same samples, same rows
    code, stdout2, _ = run_cli("critic-study", *TINY, "--variants", "film,ppo,concat", "--format", "json", "-q")
    assert code == 0
    assert json.loads(stdout2) == rows
    # the report has a critic-study section built from the stored study
    code, _, stderr = run_cli("report", "--markdown", "--out", str(tmp_path / "report"), "-q")
    assert code == 0, stderr
    text = (tmp_path / "report" / "report.md").read_text()
    assert "Critic study: the conditioning alone, the actor fixed" in text
    assert "Critic study: EV at 1 m/s" in text and "train (held out)" in text
    newest = store.read_manifest("diagnoses/critic-study")  # the second call's study (its timings differ)
    assert newest.config == manifest.config and newest.id != manifest.id
    manifest = newest
    assert f"`{manifest.id[:12]}`" in text
    # a results-only bundle of the study: its files, the actor's and rollouts' manifests without weights or logs
    bundles = tmp_path / "bundles"
    code, _, stderr = run_cli("store", "export", "diagnoses/critic-study", "--results-only", "--out", str(bundles))
    assert code == 0, stderr
    other = tmp_path / "other"
    code, _, stderr = run_cli("store", "export", "runs/film-smoke-s0", "--latest", "--out", str(bundles))
    assert code == 0, stderr
    for t in (bundles / "film-smoke-s0.tar", bundles / "critic-study.tar"):
        code, _, stderr = run_cli("store", "import", str(t), "--store", str(other))
        assert code == 0, stderr
    assert run_cli("store", "verify", "--store", str(other))[0] == 0
    copy = Store(other)
    assert copy.resolve("diagnoses/critic-study") == manifest.id
    assert copy.read_file(manifest.id, "verdicts.csv") == store.read_file(manifest.id, "verdicts.csv")
    rollout = copy.read_manifest(manifest.inputs["rollout/1/go2"])
    assert set(copy.omitted_files(rollout)) == {"rollout.mcap", "obs.npz"}
    # `store ls` counts only the files held: a rollout whose log and observations were left out weighs nothing
    sizes = {r["id"]: r["size"] for r in copy.ls("rollout")}
    assert sizes[rollout.id] == 0 and sum(f.size for f in rollout.files.values()) > 0


def test_reproduce_runs_the_study_once(store):
    from morfic_cli.pipeline import SMOKE_STUDY, Pipeline, ReproduceCfg

    cfg = ReproduceCfg(preset="smoke", variants=("film",), robots=("go2", "aliengo"), critic_study=SMOKE_STUDY)
    pipe = Pipeline(store, cfg)
    assert [k for k, _, _ in pipe.plan()][-3:] == ["critic-study", "compare", "report"]
    first = pipe.critic_study()
    assert first.status == "done"
    manifest = store.read_manifest(first.id)
    assert manifest.inputs["actor"] == store.resolve("runs/film-smoke-s0")
    assert manifest.config["seeds"] == 2 and manifest.config["commands"] == [2.0]
    second = Pipeline(store, cfg).critic_study()
    assert (second.status, second.id) == ("skipped", first.id)
    assert Pipeline(store, ReproduceCfg(preset="smoke", variants=("film",))).plan()[-3][0] == "fixed-rollout"


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (("--held-out", "4"), "--held-out"),
        (("--variants", "nope"), "variant"),
        (("--command-vx", "1.0,x"), "--command-vx"),
        (("--command-vx", "1.0,1.0"), "twice"),
        (("--actor", "runs/missing"), "runs/missing"),
    ],
)
def test_bad_input_is_an_error(run_cli, store, argv, needle):
    before = sorted(p.name for p in store.root.rglob("*"))
    code, _, stderr = run_cli("critic-study", *TINY, *argv)
    assert code == 1
    assert stderr.startswith("Error: ") and needle in stderr
    assert sorted(p.name for p in store.root.rglob("*")) == before


def _samples(reward: np.ndarray, obs_value: np.ndarray) -> Samples:
    t, n = reward.shape
    obs = {"critic": np.broadcast_to(obs_value[:, :, None, None], (t, n, 16, 48)).astype(np.float32),
           "privileged": np.zeros((t, n, 18), np.float32), "morphology": np.zeros((t, n, 11), np.float32)}
    zeros = np.zeros((t, n), bool)
    return Samples("go2", "train", obs, np.zeros((t, n, 12), np.float32), reward.astype(np.float32),
                   np.zeros((t, n), np.float32), zeros, zeros, "id", False)


def test_fit_data_window_stride_and_standardisation():
    # gamma 0.5, eps 0.25 -> H_eps = 2: with T = 5 the window is t <= 3; stride 2 keeps t = 0, 2.
    reward = np.ones((5, 2))
    data = cs.fit_data([_samples(reward, np.zeros((5, 2)))], 0.5, DiagnoseCfg(trunc_eps=0.25), stride=2)
    # G[t] = sum_{k=t}^{4} 0.5^(k-t): G[0] = 1.9375, G[2] = 1.75, for both envs, row-major over (t, env)
    assert data.G.tolist() == pytest.approx([1.9375, 1.9375, 1.75, 1.75])
    assert data.g_mean == pytest.approx(1.84375)
    assert data.g_std == pytest.approx(0.09375)
    assert data.target.tolist() == pytest.approx([1.0, 1.0, -1.0, -1.0])


def test_split_train_keeps_the_last_envs_out():
    s = _samples(np.arange(12.0).reshape(3, 4), np.zeros((3, 4)))
    fit, held = cs.split_train(s, 1)
    assert fit.reward.shape == (3, 3) and held.reward.shape == (3, 1)
    assert held.reward[:, 0].tolist() == [3.0, 7.0, 11.0]
    assert held.obs["critic"].shape == (3, 1, 16, 48)


def test_a_fitted_critic_learns_a_return_its_input_tells():
    # two kinds of state (input 0 or 1) with returns 10 and 20: a critic regressed on them predicts both
    g_values = torch.tensor([10.0, 20.0]).repeat(64)
    x = torch.tensor([0.0, 1.0]).repeat(64)
    from tensordict import TensorDict

    obs = TensorDict({"critic": x[:, None, None].expand(128, 16, 48).clone(),
                      "privileged": torch.zeros(128, 18), "morphology": torch.zeros(128, 11)}, batch_size=[128])
    data = cs.FitData(obs, g_values, 15.0, 5.0)
    from morfic_cli.rl.config import smoke_preset

    critic = cs.build_critic(smoke_preset("film"), "ppo", seed=0)
    cfg = cs.StudyCfg(epochs=60, minibatch=32, learning_rate=1e-3)
    losses, _ = cs.fit_critic(critic, data, cfg, seed=0)
    assert losses[-1] < 0.01 * losses[0]
    v = cs.Denormalized(critic, data.g_mean, data.g_std)(obs[:2]).reshape(-1)
    assert v.tolist() == pytest.approx([10.0, 20.0], abs=0.5)


def test_canonical_variants_fold_actor_only_into_ppo():
    assert cs.canonical_variants(["actor-only", "film", "ppo", "concat"]) == ["ppo", "film", "concat"]


def _rows(values: dict[tuple[str, str], list[float]], metric: str) -> list[dict]:
    out = []
    for (variant, robot), vals in values.items():
        for seed, v in enumerate(vals):
            out.append({"command_vx": 1.0, "robot": robot, "variant": variant, "fit_seed": seed,
                        "multiplicative": variant in ("film", "adaln"), "ev": math.nan, "flip": math.nan,
                        "cos_grad": math.nan, "abs_nvb": 0.0, "nve": 0.0} | {metric: v})
    return out


def test_claim_a_effect_by_hand():
    # aliengo: film 0.5, adaln 0.3 (multiplicative mean 0.4); ppo 0.1 -> +0.3, constant seeds: exact, p 0
    # mini_cheetah: film {0, 0.2}, adaln {0, 0.2} (mean 0.1, s² 0.02 each), ppo 0.1 constant: effect 0,
    # t 0 -> p 1. Holm over the two robots: 0 and 1.
    rows = _rows({("film", "aliengo"): [0.5, 0.5], ("adaln", "aliengo"): [0.3, 0.3], ("ppo", "aliengo"): [0.1, 0.1],
                  ("film", "mini_cheetah"): [0.0, 0.2], ("adaln", "mini_cheetah"): [0.0, 0.2],
                  ("ppo", "mini_cheetah"): [0.1, 0.1]}, "ev")
    claim = ss.claim_a(rows, 1.0)
    by_robot = {r["robot"]: r for r in claim["robots"]}
    e = by_robot["aliengo"]["effect"]
    assert (e.estimate, e.lo, e.hi, e.p) == (pytest.approx(0.3), pytest.approx(0.3), pytest.approx(0.3), 0.0)
    assert by_robot["aliengo"]["verdict"] == stats.HOLDS
    assert by_robot["mini_cheetah"]["effect"].estimate == pytest.approx(0.0)
    assert by_robot["mini_cheetah"]["p_holm"] == pytest.approx(1.0)
    assert by_robot["mini_cheetah"]["verdict"] == stats.CANNOT
    assert "anymal_c" not in by_robot  # no rows: left out of the claim
    assert claim["verdict"] == ss.PARTLY


def test_claim_c_needs_film_best_against_every_critic():
    flip = _rows({("film", "aliengo"): [0.2, 0.2], ("ppo", "aliengo"): [0.3, 0.3], ("adaln", "aliengo"): [0.1, 0.1]},
                 "flip")
    cos = _rows({("film", "aliengo"): [0.5, 0.5], ("ppo", "aliengo"): [0.4, 0.4], ("adaln", "aliengo"): [0.4, 0.4]},
                "cos_grad")
    for r, c in zip(flip, cos, strict=True):
        r["cos_grad"] = c["cos_grad"]
    claim = ss.claim_c(flip, 1.0)
    assert [r["robot"] for r in claim["robots"]] == ["aliengo"]  # mini_cheetah: no rows, left out
    aliengo = claim["robots"][0]
    pairs = {p["other"]: p for p in aliengo["pairs"]}
    assert pairs["ppo"]["flip"].estimate == pytest.approx(0.1)  # ppo - film
    assert pairs["adaln"]["flip"].estimate == pytest.approx(-0.1)  # adaln flips less than film: reversed
    assert pairs["adaln"]["cos_grad"].estimate == pytest.approx(0.1)
    # every seed constant: every comparison exact (p 0): 3 for, adaln's Flip against -> mixed
    assert pairs["adaln"]["flip_verdict"] == stats.NOT and pairs["ppo"]["flip_verdict"] == stats.HOLDS
    assert aliengo["verdict"] == ss.MIXED and claim["verdict"] == ss.MIXED
    rows = ss.verdict_rows([claim])
    assert [r["verdict"] for r in rows] == [stats.HOLDS, stats.HOLDS, stats.NOT, stats.HOLDS]
    assert set(ss.VERDICT_COLUMNS) == set(rows[0])


def test_a_users_critic_is_in_neither_group_of_claim_a():
    rows = _rows({("film", "aliengo"): [0.5, 0.5], ("ppo", "aliengo"): [0.1, 0.1], ("mine", "aliengo"): [9.0, 9.0]},
                 "ev")
    for r in rows:
        if r["variant"] == "mine":
            r["multiplicative"] = float("nan")  # as a CSV with an empty cell reads back
    effect = ss.claim_a(rows, 1.0)["robots"][0]["effect"]
    assert effect.estimate == pytest.approx(0.4) and (effect.n_a, effect.n_b) == (2, 2)
    assert [ss.group_of(v) for v in (True, "False", None, float("nan"), "true")] == [True, False, None, None, True]
