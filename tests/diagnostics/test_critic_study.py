"""`morfic critic-study`: fits to convergence on frozen actors' data, scored per robot; verdicts over actors."""

from __future__ import annotations

import csv
import io
import json
import math
import statistics

import numpy as np
import pytest
import torch
from smoke_runs import copy_store

from morfic_cli.diagnostics import critic_study as cs
from morfic_cli.diagnostics import study_summary as ss
from morfic_cli.diagnostics.samples import DiagnoseCfg, Samples
from morfic_cli.errors import MorficError
from morfic_cli.report import stats
from morfic_cli.store import Store

pytestmark = pytest.mark.usefixtures("one_torch_thread")

ACTORS = ("runs/film-smoke-s0", "runs/film-smoke-s1", "runs/concat-smoke-s0")
# --trunc-eps 0.8 -> H_eps = ceil(ln 0.8 / ln 0.99) = 23, so 30 steps leave the window t <= 7. 5 training envs:
# 3 fitted, 1 validation, 1 held out ('train').
TINY = (
    "--train-envs",
    "5",
    "--held-out",
    "1",
    "--val-envs",
    "1",
    "--target-envs",
    "2",
    "--steps",
    "30",
    "--trunc-eps",
    "0.8",
    "--max-epochs",
    "30",
    "--patience",
    "2",
    "--minibatch",
    "8",
    "--stride",
    "2",
    "--seeds",
    "2",
    "--robots",
    "go2,aliengo",
    "--command-vx",
    "1.0",
)


@pytest.fixture(scope="module")
def smoke_store(smoke_runs):
    """film and concat seed 0 (reproduce's fixed-rollout actor), then film seed 1: the session's template, copied
    per test."""
    return smoke_runs.template(
        (("film", "concat"), 0, "{variant}-smoke-s{seed}"), (("film",), 1, "{variant}-smoke-s{seed}")
    )


@pytest.fixture
def store(smoke_store, tmp_path, monkeypatch):
    return copy_store(smoke_store, tmp_path, monkeypatch)


def _csv(store, manifest_id, name):
    return list(csv.DictReader(io.StringIO(store.read_file(manifest_id, name).decode())))


def test_study_over_actors_rows_files_and_verdicts(run_cli, store, tmp_path):
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(
        "critic-study",
        *TINY,
        "--actors",
        ",".join(ACTORS),
        "--min-ev",
        "-1000",
        "--variants",
        "film,actor-only,concat",
        "--out",
        str(out),
        "--format",
        "json",
    )
    assert code == 0, stderr
    rows = json.loads(stdout)
    # 1 command x (train + 2 robots) x 3 critics (actor-only folded into ppo) = 9 cells, each over 3 actors
    assert len(rows) == 9
    assert {r["variant"] for r in rows} == {"film", "ppo", "concat"}
    assert {r["robot"] for r in rows} == {"train", "go2", "aliengo"}
    manifest = store.read_manifest("diagnoses/critic-study")
    assert manifest.config["layout"] == cs.STUDY_LAYOUT == 2 and manifest.config["actors"] == list(ACTORS)
    assert set(manifest.files) == {"critic_study.csv", "summary.csv", "verdicts.csv", "fits.csv", "critic_study.png"}
    names = [a.removeprefix("runs/") for a in ACTORS]
    assert set(manifest.inputs) == {f"actor/{n}" for n in names} | {
        f"rollout/{n}/1/{r}" for n in names for r in ("train", "go2", "aliengo")
    }
    study = _csv(store, manifest.id, "critic_study.csv")
    assert len(study) == 3 * 3 * 3 * 2  # actors x critics x robots x fit seeds
    # the train rows are the held-out env: 1 env x window t <= 7 = 8 samples; a target robot has 2 envs x 8
    assert {int(r["n_samples"]) for r in study if r["robot"] == "train"} == {8}
    assert {int(r["n_samples"]) for r in study if r["robot"] == "go2"} == {16}
    fits = _csv(store, manifest.id, "fits.csv")
    # fit set: 3 envs x steps {0, 2, 4, 6} of the window = 12 samples; validation: 1 env x 4 = 4
    assert {(int(r["n_train"]), int(r["n_val"])) for r in fits} == {(12, 4)}
    by_fit: dict[tuple, list[dict]] = {}
    for r in fits:
        by_fit.setdefault((r["actor"], r["variant"], r["fit_seed"]), []).append(r)
    assert len(by_fit) == 3 * 3 * 2
    for curve in by_fit.values():  # early stopping: the run ends `patience` epochs after its best validation loss
        best = int(curve[0]["best_epoch"])
        val = [float(r["val_loss"]) for r in curve]
        assert curve[0]["stopped_early"] == "True" and len(curve) == best + 2
        assert val[best - 1] == min(val[:best]) and all(v >= val[best - 1] - 1e-3 for v in val[best:])
    assert all(r["converged"] == "True" for r in study)  # --min-ev -1000: every fit that stopped is kept
    # a cell: each actor's two fits averaged first, then the three actors -> n 3, the t interval over them
    cell = next(r for r in rows if (r["robot"], r["variant"]) == ("aliengo", "film"))
    per_actor = [
        statistics.mean(
            float(r["ev"]) for r in study if (r["actor"], r["robot"], r["variant"]) == (n, "aliengo", "film")
        )
        for n in names
    ]
    mean, lo, hi = stats.mean_interval(per_actor)
    assert cell["n"] == 3 and cell["ev_mean"] == pytest.approx(mean) and cell["ev_lo"] == pytest.approx(lo)
    verdicts = _csv(store, manifest.id, "verdicts.csv")
    assert {r["unit"] for r in verdicts} == {ss.ACTOR} and {r["n_a"] for r in verdicts} == {"3"}
    assert (out / "verdicts.csv").exists() and (out / "critic_study.png").read_bytes()[:4] == b"\x89PNG"
    assert "claim (a) at 1 m/s" in stderr and "claim (c) at 1 m/s" in stderr and "all 18 fits converged" in stderr
    # a second call reuses the stored rollouts and refits: same rows
    code, stdout2, _ = run_cli(
        "critic-study",
        *TINY,
        "--actors",
        ",".join(ACTORS),
        "--min-ev",
        "-1000",
        "--variants",
        "film,ppo,concat",
        "--format",
        "json",
        "-q",
    )
    assert code == 0
    assert json.loads(stdout2) == rows
    # a threshold between the fits' validation EVs flags those below it: left out of the cells, counted
    kept_ev = {k: float(c[int(c[0]["best_epoch"]) - 1]["val_ev"]) for k, c in by_fit.items()}  # the kept epoch's
    assert kept_ev == {k: float(r["val_ev"]) for r in study for k in [(r["actor"], r["variant"], r["fit_seed"])]}
    threshold = sorted(kept_ev.values())[len(kept_ev) // 2]
    code, stdout3, stderr3 = run_cli(
        "critic-study",
        *TINY,
        "--actors",
        ",".join(ACTORS),
        "--min-ev",
        str(threshold),
        "--variants",
        "film,ppo,concat",
        "--format",
        "json",
    )
    assert code == 0, stderr3
    flagged = {k for k, ev in kept_ev.items() if ev < threshold}
    assert 0 < len(flagged) < len(by_fit)
    assert f"{len(flagged)} of 18 fits unconverged" in stderr3
    newest = store.read_manifest("diagnoses/critic-study")
    study3 = _csv(store, newest.id, "critic_study.csv")
    assert {(r["actor"], r["variant"], r["fit_seed"]) for r in study3 if r["converged"] == "False"} == flagged
    for cell in json.loads(stdout3):
        mine = [r for r in study3 if (r["robot"], r["variant"]) == (cell["robot"], cell["variant"])]
        kept = {n: [float(r["ev"]) for r in mine if r["actor"] == n and r["converged"] == "True"] for n in names}
        units = [statistics.mean(v) for v in kept.values() if v]
        assert cell["n"] == len(units) and cell["n_flagged"] == sum(r["converged"] == "False" for r in mine)
        if units:
            assert cell["ev_mean"] == pytest.approx(statistics.mean(units))
    # the report has a critic-study section built from the newest stored study
    code, _, stderr = run_cli("report", "--markdown", "--out", str(tmp_path / "report"), "-q")
    assert code == 0, stderr
    text = (tmp_path / "report" / "report.md").read_text()
    assert "Critic study: the conditioning alone, the actor fixed" in text
    assert "Critic study: EV at 1 m/s" in text and "Critic study: NVE at 1 m/s" in text and "train (held out)" in text
    assert f"`{newest.id[:12]}`" in text and "3 actors" in text and "unconverged and left out" in text
    # a results-only bundle of the study: its files, the actors' and rollouts' manifests without weights or logs
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
    assert copy.resolve("diagnoses/critic-study") == newest.id
    assert copy.read_file(newest.id, "verdicts.csv") == store.read_file(newest.id, "verdicts.csv")
    rollout = copy.read_manifest(newest.inputs["rollout/film-smoke-s0/1/go2"])
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
    # the study's actors: film seeds 0-2, actor-only and concat seed 0 of the preset, those reproduced or stored
    assert manifest.config["actors"] == list(ACTORS)
    assert {k: v for k, v in manifest.inputs.items() if k.startswith("actor/")} == {
        f"actor/{a.removeprefix('runs/')}": store.resolve(a) for a in ACTORS
    }
    assert manifest.config["seeds"] == 2 and manifest.config["commands"] == [2.0]
    second = Pipeline(store, cfg).critic_study()
    assert (second.status, second.id) == ("skipped", first.id)
    assert Pipeline(store, ReproduceCfg(preset="smoke", variants=("film",))).plan()[-3][0] == "fixed-rollout"


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (("--held-out", "4"), "--held-out"),
        (("--val-envs", "4"), "--val-envs"),
        (("--min-ev", "2"), "--min-ev"),
        (("--actors", "runs/film-smoke-s0,runs/film-smoke-s0"), "twice"),
        (("--variants", "nope"), "variant"),
        (("--command-vx", "1.0,x"), "--command-vx"),
        (("--command-vx", "1.0,1.0"), "twice"),
        (("--actor", "runs/missing"), "runs/missing"),
    ],
)
def test_bad_input_is_an_error(run_cli, store, argv, needle):
    before = sorted(p.name for p in store.root.rglob("*"))
    code, _, stderr = run_cli("critic-study", *TINY, "--actors", "runs/film-smoke-s0", *argv)
    assert code == 1
    assert stderr.startswith("Error: ") and needle in stderr
    assert sorted(p.name for p in store.root.rglob("*")) == before


def _samples(reward: np.ndarray, obs_value: np.ndarray) -> Samples:
    t, n = reward.shape
    obs = {
        "critic": np.broadcast_to(obs_value[:, :, None, None], (t, n, 16, 48)).astype(np.float32),
        "privileged": np.zeros((t, n, 18), np.float32),
        "morphology": np.zeros((t, n, 11), np.float32),
    }
    zeros = np.zeros((t, n), bool)
    return Samples(
        "go2",
        "train",
        obs,
        np.zeros((t, n, 12), np.float32),
        reward.astype(np.float32),
        np.zeros((t, n), np.float32),
        zeros,
        zeros,
        "id",
        False,
    )


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
    s = _samples(np.arange(15.0).reshape(3, 5), np.zeros((3, 5)))
    fit, val, held = cs.split_train(s, 1, 2)
    assert fit.reward.shape == (3, 2) and val.reward.shape == (3, 2) and held.reward.shape == (3, 1)
    assert val.reward[:, 0].tolist() == [2.0, 7.0, 12.0] and held.reward[:, 0].tolist() == [4.0, 9.0, 14.0]
    assert held.obs["critic"].shape == (3, 1, 16, 48)


def test_early_stopping_stops_at_the_right_epoch():
    # patience 2, min_delta 0.005: epochs 1-3 improve (1.0, 0.5, 0.4); 0.41 does not; 0.399 is not below
    # 0.4 - 0.005 = 0.395 either -> two epochs without an improvement: stop after epoch 5, keep epoch 3
    stop = cs.EarlyStopping(patience=2, min_delta=0.005)
    assert [stop.update(x) for x in (1.0, 0.5, 0.4, 0.41, 0.399)] == [False, False, False, False, True]
    assert (stop.best_epoch, stop.best, stop.epoch) == (3, 0.4, 5)
    # patience 3 goes on; 0.39 at epoch 6 improves (< 0.395), so 7, 8, 9 without one stop it at 9
    stop = cs.EarlyStopping(patience=3, min_delta=0.005)
    seq = (1.0, 0.5, 0.4, 0.41, 0.399, 0.39, 0.5, float("nan"), 0.389)
    assert [stop.update(x) for x in seq] == [False] * 8 + [True]
    assert stop.best_epoch == 6


def _constant_data(g: list[float]) -> cs.FitData:
    from tensordict import TensorDict

    n = len(g)
    obs = TensorDict(
        {"critic": torch.zeros(n, 16, 48), "privileged": torch.zeros(n, 18), "morphology": torch.zeros(n, 11)},
        batch_size=[n],
    )
    G = torch.tensor(g)
    return cs.FitData(obs, G, float(G.mean()), float(G.std(correction=0)))


def test_a_fit_that_cannot_explain_the_validation_envs_is_flagged():
    # every input is the same state, so a critic predicts one value c for all: the validation EV is
    # 1 - Var(G - c) / Var(G) = 0 exactly, below --min-ev 0.1: flagged; at --min-ev -0.5 it is kept
    from morfic_cli.rl.config import smoke_preset

    data, val = _constant_data([1.0, 3.0] * 16), _constant_data([0.0, 4.0, 2.0, 2.0])
    cfg = cs.StudyCfg(max_epochs=200, patience=3, minibatch=8, min_ev=0.1)
    fit = cs.fit_critic(cs.build_critic(smoke_preset("film"), "ppo", seed=0), data, cfg, 0, val)
    assert fit.stopped_early and len(fit.losses) == fit.best_epoch + 3 == len(fit.val_evs)
    assert fit.val_ev == pytest.approx(0.0, abs=1e-6)
    assert not fit.converged
    assert dataclasses_replace_min_ev(fit, -0.5).converged
    # the critic keeps its best epoch's weights: its validation loss now is that epoch's
    pred = fit.critic(val.obs).reshape(-1).detach()
    assert float(torch.nn.functional.mse_loss(pred, val.target_as(data))) == pytest.approx(
        fit.val_losses[fit.best_epoch - 1], rel=1e-5
    )
    # a fit the cap cuts short is not converged whatever its EV
    short = cs.fit_critic(
        cs.build_critic(smoke_preset("film"), "ppo", seed=0),
        data,
        cs.StudyCfg(max_epochs=2, patience=5, minibatch=8, min_ev=-1.0),
        0,
        val,
    )
    assert (len(short.losses), short.stopped_early, short.converged) == (2, False, False)


def dataclasses_replace_min_ev(fit: cs.Fit, min_ev: float) -> cs.Fit:
    import dataclasses

    return dataclasses.replace(fit, min_ev=min_ev)


def test_averaging_within_actor_then_across_actors_leaves_flagged_fits_out():
    # actor A: fits 0.2, 0.4 -> 0.3; B: 0.5 and a flagged 9.0 -> 0.5; C: 0.1, 0.3 -> 0.2; D: every fit flagged.
    # Over actors: mean(0.3, 0.5, 0.2) = 1/3, n 3 (pooling the kept fits would give 0.3), 3 fits left out.
    fits = {
        "A": [(0.2, True), (0.4, True)],
        "B": [(0.5, True), (9.0, False)],
        "C": [(0.1, True), (0.3, True)],
        "D": [(7.0, False)],
    }
    rows = [
        {
            "command_vx": 1.0,
            "robot": "aliengo",
            "variant": "film",
            "fit_seed": k,
            "multiplicative": True,
            "actor": actor,
            "converged": str(ok),
            "ev": ev,
            "nvb": 0.0,
            "abs_nvb": 0.0,
            "nve": 1.0,
            "flip": 0.1,
            "cos_grad": 0.5,
        }
        for actor, vals in fits.items()
        for k, (ev, ok) in enumerate(vals)
    ]
    assert ss.study_unit(rows) == ss.ACTOR
    assert ss.unit_values(rows, "ev") == pytest.approx([0.3, 0.5, 0.2])
    cell = next(c for c in ss.cell_summary(rows) if c["metric"] == "ev")
    # t interval over the 3 actor means: s = sqrt(((0.3-1/3)^2 + (0.5-1/3)^2 + (0.2-1/3)^2) / 2) = 0.152753,
    # half-width t(0.975, 2) * s / sqrt(3) = 4.302653 * 0.0881917 = 0.379458
    assert (cell["mean"], cell["n"], cell["n_fits"], cell["n_flagged"]) == (pytest.approx(1 / 3), 3, 5, 2)
    assert cell["lo"] == pytest.approx(1 / 3 - 0.379458, abs=1e-6) and cell["hi"] == pytest.approx(
        1 / 3 + 0.379458, abs=1e-6
    )
    assert ss.flagged(rows) == [("B", "film", 1), ("D", "film", 0)]
    assert ss.convergence_text(rows).startswith("2 of 7 fits unconverged and left out")


def test_claims_over_actors_are_paired_by_actor():
    # film - ppo Flip per actor: ppo (0.5, 0.6, 0.4) - film (0.2, 0.4, 0.3) = (0.3, 0.2, 0.1): mean 0.2,
    # s^2 = 0.01, SE = 0.1 / sqrt(3) = 0.057735, t = 3.4641 on 2 df -> p = 0.07418 (Welch over the same values,
    # ignoring the pairing, would give p 0.25)
    flips = {"film": (0.2, 0.4, 0.3), "ppo": (0.5, 0.6, 0.4)}
    rows = [
        {
            "command_vx": 1.0,
            "robot": "aliengo",
            "variant": v,
            "fit_seed": 0,
            "multiplicative": v == "film",
            "actor": f"a{i}",
            "converged": "True",
            "flip": f,
            "cos_grad": 0.5,
            "ev": 0.1,
            "nve": 1.0,
            "nvb": 0.0,
        }
        for v, fs in flips.items()
        for i, f in enumerate(fs)
    ]
    e = ss.contrast_effect(rows, "flip", ["ppo"], ["film"], robot="aliengo")
    assert (e.estimate, e.se, e.df, e.n_a) == (pytest.approx(0.2), pytest.approx(0.0577350), 2.0, 3)
    assert e.p == pytest.approx(0.0741799, abs=1e-6)
    assert e.lo == pytest.approx(0.2 - 4.302653 * 0.0577350, abs=1e-6)
    pair = ss.claim_c(rows, 1.0)["robots"][0]["pairs"][0]
    assert pair["other"] == "ppo" and pair["flip"].p == pytest.approx(0.0741799, abs=1e-6)
    # an actor whose ppo fits were all flagged drops out of that comparison: 2 actors remain
    rows[3]["converged"] = "False"
    assert ss.contrast_effect(rows, "flip", ["ppo"], ["film"], robot="aliengo").n_a == 2


def test_the_unit_is_named_with_its_fit_seeds():
    from morfic_cli.report.study import _unit_words

    row = {"command_vx": 1.0, "robot": "go2", "variant": "film", "converged": "True", "ev": 0.1}
    one = [{**row, "actor": a, "fit_seed": 0} for a in ("a0", "a1", "a2")]
    two = one + [{**r, "fit_seed": 1} for r in one]
    assert _unit_words(one) == "3 actors (one fit a critic and actor)"
    assert _unit_words(two) == "3 actors (each actor's converged fits, 2 fit seeds, averaged first)"


def test_a_one_actor_study_of_layout_1_is_read_over_fit_seeds_and_a_newer_layout_refused():
    rows = [
        {
            "command_vx": 1.0,
            "robot": "aliengo",
            "variant": "film",
            "fit_seed": k,
            "multiplicative": True,
            "actor": "film-cpu-s0",
            "ev": ev,
        }
        for k, ev in enumerate((0.1, 0.3))
    ]
    assert ss.study_unit(rows) == ss.FIT_SEED and ss.unit_values(rows, "ev") == [0.1, 0.3]
    assert "layout 1" in ss.convergence_text(rows)
    assert cs.check_layout({}) == 1 and cs.check_layout({"layout": 2}) == 2
    with pytest.raises(MorficError, match="layout 3"):
        cs.check_layout({"layout": 3})


def test_a_fitted_critic_learns_a_return_its_input_tells():
    # two kinds of state (input 0 or 1) with returns 10 and 20: a critic regressed on them predicts both
    g_values = torch.tensor([10.0, 20.0]).repeat(64)
    x = torch.tensor([0.0, 1.0]).repeat(64)
    from tensordict import TensorDict

    obs = TensorDict(
        {
            "critic": x[:, None, None].expand(128, 16, 48).clone(),
            "privileged": torch.zeros(128, 18),
            "morphology": torch.zeros(128, 11),
        },
        batch_size=[128],
    )
    data = cs.FitData(obs, g_values, 15.0, 5.0)
    from morfic_cli.rl.config import smoke_preset

    critic = cs.build_critic(smoke_preset("film"), "ppo", seed=0)
    cfg = cs.StudyCfg(max_epochs=60, minibatch=32, learning_rate=1e-3)
    losses = cs.fit_critic(critic, data, cfg, seed=0).losses  # no validation set: every epoch of the cap
    assert len(losses) == 60 and losses[-1] < 0.01 * losses[0]
    v = cs.Denormalized(critic, data.g_mean, data.g_std)(obs[:2]).reshape(-1)
    assert v.tolist() == pytest.approx([10.0, 20.0], abs=0.5)


def test_canonical_variants_fold_actor_only_into_ppo():
    assert cs.canonical_variants(["actor-only", "film", "ppo", "concat"]) == ["ppo", "film", "concat"]


def _rows(values: dict[tuple[str, str], list[float]], metric: str) -> list[dict]:
    out = []
    for (variant, robot), vals in values.items():
        for seed, v in enumerate(vals):
            out.append(
                {
                    "command_vx": 1.0,
                    "robot": robot,
                    "variant": variant,
                    "fit_seed": seed,
                    "multiplicative": variant in ("film", "adaln"),
                    "ev": math.nan,
                    "flip": math.nan,
                    "cos_grad": math.nan,
                    "abs_nvb": 0.0,
                    "nvb": 0.0,
                    "nve": 0.0,
                }
                | {metric: v}
            )
    return out


def test_claim_a_effect_by_hand():
    # aliengo: film 0.5, adaln 0.3 (multiplicative mean 0.4); ppo 0.1 -> +0.3, constant seeds: exact, p 0
    # mini_cheetah: film {0, 0.2}, adaln {0, 0.2} (mean 0.1, s² 0.02 each), ppo 0.1 constant: effect 0,
    # t 0 -> p 1. Holm over the two robots: 0 and 1.
    rows = _rows(
        {
            ("film", "aliengo"): [0.5, 0.5],
            ("adaln", "aliengo"): [0.3, 0.3],
            ("ppo", "aliengo"): [0.1, 0.1],
            ("film", "mini_cheetah"): [0.0, 0.2],
            ("adaln", "mini_cheetah"): [0.0, 0.2],
            ("ppo", "mini_cheetah"): [0.1, 0.1],
        },
        "ev",
    )
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
    flip = _rows(
        {("film", "aliengo"): [0.2, 0.2], ("ppo", "aliengo"): [0.3, 0.3], ("adaln", "aliengo"): [0.1, 0.1]}, "flip"
    )
    cos = _rows(
        {("film", "aliengo"): [0.5, 0.5], ("ppo", "aliengo"): [0.4, 0.4], ("adaln", "aliengo"): [0.4, 0.4]}, "cos_grad"
    )
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
    rows = _rows(
        {("film", "aliengo"): [0.5, 0.5], ("ppo", "aliengo"): [0.1, 0.1], ("mine", "aliengo"): [9.0, 9.0]}, "ev"
    )
    for r in rows:
        if r["variant"] == "mine":
            r["multiplicative"] = float("nan")  # as a CSV with an empty cell reads back
    effect = ss.claim_a(rows, 1.0)["robots"][0]["effect"]
    assert effect.estimate == pytest.approx(0.4) and (effect.n_a, effect.n_b) == (2, 2)
    assert [ss.group_of(v) for v in (True, "False", None, float("nan"), "true")] == [True, False, None, None, True]
