"""scripts/results_tables.py: run CSVs -> docs/results.md's tables, with the paper's columns beside them."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "results_tables.py"
spec = importlib.util.spec_from_file_location("results_tables", SCRIPT)
rt = importlib.util.module_from_spec(spec)
spec.loader.exec_module(rt)

EVAL_HEAD = "robot,mode,command_vx,d,vx_mean,vx_std,survival,verdict\n"


def _runs(tmp_path: Path) -> Path:
    (tmp_path / "film-cpu-s0-eval.csv").write_text(EVAL_HEAD + "aliengo,descriptor,2.0,0.324,1.6449,0.6351,0.0,falls\n")
    (tmp_path / "ppo-cpu-s0-eval.csv").write_text(EVAL_HEAD + "aliengo,descriptor,2.0,0.324,1.2,0.48,0.421875,falls\n")
    (tmp_path / "film-cpu-s0-calibration.csv").write_text(
        "robot,ev,abs_nvb,nve,asa\ngo2,0.37296,0.33255,0.85886,0.53106\n"
    )
    return tmp_path


def test_transfer_table_orders_runs_as_the_paper_and_adds_its_columns(tmp_path):
    lines = rt.transfer_table(rt.load(_runs(tmp_path), "eval"), "descriptor", 2.0)
    assert lines[0] == "| robot | d | `ppo` (s0) | `film` (s0) | paper ppo | paper film |"
    # ours rounded to 2/2/3 places with the verdict; the paper's AlienGo cells (zero-shot table)
    assert lines[2] == (
        "| aliengo | 0.324 | 1.20 ± 0.48 / 0.422 (falls) | 1.64 ± 0.64 / 0.000 (falls) | "
        "0.27 ± 0.07 / 0.000 | 1.98 ± 0.51 / 1.000 |"
    )


def test_seeds_of_a_variant_pool_into_mean_and_std(tmp_path):
    """Seeds 0-2 of film become one column: mean ± population std of v_x and of S over the seeds (n=3)."""
    _runs(tmp_path)
    for seed, vx, s in ((1, 1.0, 0.5), (2, 1.3, 0.25)):
        (tmp_path / f"film-cpu-s{seed}-eval.csv").write_text(
            EVAL_HEAD + f"aliengo,descriptor,2.0,0.324,{vx},0.5,{s},falls\n"
        )
    lines = rt.transfer_table(rt.load(tmp_path, "eval"), "descriptor", 2.0)
    assert lines[0] == "| robot | d | `ppo` (s0) | `film` (n=3) | paper ppo | paper film |"
    # v_x 1.6449, 1.0, 1.3: mean 1.3150, std sqrt(((.3299)^2 + (.315)^2 + (.015)^2) / 3) = 0.2634
    # S 0.0, 0.5, 0.25: mean 0.25, std sqrt((.0625 + .0625 + 0) / 3) = 0.2041
    assert "| 1.31 ± 0.26 / 0.250 ± 0.204 (n=3) |" in lines[2]


def test_claims_are_computed_from_the_csvs_with_their_artifact_ids(tmp_path):
    _runs(tmp_path)
    (tmp_path / "film-cpu-s0-artifacts.json").write_text(json.dumps({"eval": "e" * 64}))
    text = rt.render_claims(tmp_path)
    # (b) on AlienGo: film 1.6449 x 0.0 = 0.00 against ppo 1.2 x 0.421875 = 0.51, one seed each: no test
    assert "**(b) MorFiC-F transfers better" in text and "Verdict: **does not hold**" not in text
    assert "film - ppo -0.51 (n 1 vs 1: no test)" in text
    assert "film 0.00 (v_x 1.64, S 0.00), ppo 0.51 (v_x 1.20, S 0.42)" in text  # one seed: no n
    assert "`eeeeeeeeeeee`" in text and "`ppo-cpu-s0-eval.csv`" in text  # an id, else the file it came from


def test_claims_are_judged_at_2_and_at_1_m_s_from_the_eval_1_0_files(tmp_path):
    """Seeds 0-1 alike (a point interval): film loses at 2.0 m/s on AlienGo and wins at 1.0 m/s."""
    _runs(tmp_path)
    for seed in (0, 1):
        if seed:
            for run in ("film", "ppo"):
                src = (tmp_path / f"{run}-cpu-s0-eval.csv").read_text()
                (tmp_path / f"{run}-cpu-s1-eval.csv").write_text(src)
        (tmp_path / f"film-cpu-s{seed}-eval-1.0.csv").write_text(
            EVAL_HEAD + "aliengo,descriptor,1.0,0.324,0.9,0.1,1.0,walks\n"
        )
        (tmp_path / f"ppo-cpu-s{seed}-eval-1.0.csv").write_text(
            EVAL_HEAD + "aliengo,descriptor,1.0,0.324,0.5,0.1,0.8,walks\n"
        )
    (tmp_path / "film-cpu-s0-artifacts.json").write_text(json.dumps({"eval": "e" * 64, "eval-1.0": "f" * 64}))
    # the tables read <run>-eval.csv only; the claims both
    assert set(rt.load(tmp_path, "eval")["command_vx"]) == {2.0}
    assert sorted(set(rt.load_evals(tmp_path)["command_vx"])) == [1.0, 2.0]
    text = rt.render_claims(tmp_path)
    assert text.startswith("| claim | 2.0 m/s | 1.0 m/s |\n|---|---|---|\n")
    # 2.0 m/s: 0.00 - 0.51 on AlienGo, exact (both sides repeat one value): 1 of 9 comparisons against, the
    # others without a test -> partly reversed; 1.0 m/s: 0.90 - 0.40 beats ppo, 1 of 9 for -> holds partly
    assert (
        "| (b) MorFiC-F transfers better than ppo, actor-only, concat | **partly reversed** | **holds partly** |"
        in text
    )
    at2, at1 = text.split("### At 2.0 m/s")[1].split("### At 1.0 m/s")
    assert "film - ppo -0.51 [-0.51, -0.51] (n 2 vs 2, p 0, Holm 0)" in at2 and "`eeeeeeeeeeee`" in at2
    assert "**(b) MorFiC-F transfers better than PPO, actor-only and concat (v_x x S at 1.0 m/s" in at1
    assert (
        "film - ppo +0.50 [+0.50, +0.50] (n 2 vs 2, p 0, Holm 0); film - actor-only (no test: actor-only not evaluated)"
    ) in at1
    assert "`ffffffffffff`" in at1 and "`film-cpu-s1-eval-1.0.csv`" in at1 and "eeeeeeeeeeee" not in at1


def test_claim_a_is_judged_at_1_m_s_from_the_calibration_1_0_files(tmp_path):
    """Two seeds alike (a point interval): on AlienGo film's EV 0.6 against concat's 0.2 at 1.0 m/s -> +0.40."""
    _runs(tmp_path)
    head = "robot,command_vx,ev,abs_nvb,nve,asa\n"
    for seed in (0, 1):
        for run, ev in (("film", 0.6), ("concat", 0.2)):
            (tmp_path / f"{run}-cpu-s{seed}-calibration-1.0.csv").write_text(head + f"aliengo,1.0,{ev},0.1,0.9,0.8\n")
    (tmp_path / "film-cpu-s0-artifacts.json").write_text(json.dumps({"diagnosis-1.0": "d" * 64}))
    # the claims are judged at the commands of the evals (check_claims)
    (tmp_path / "film-cpu-s0-eval-1.0.csv").write_text(EVAL_HEAD + "aliengo,descriptor,1.0,0.324,0.9,0.1,1.0,walks\n")
    # the 2.0 m/s table and figures read <run>-calibration.csv only; the claims both
    assert set(rt.load(tmp_path, "calibration")["robot"]) == {"go2"}
    assert len(rt.load_calibrations(tmp_path)) == 5
    _, cal, _ = rt.claim_rows(tmp_path)
    ids = {(r["run"], r["robot"]): r["artifact"] for r in cal}
    assert ids[("film-cpu-s0", "aliengo")] == "d" * 64  # its artifact id, else the file it came from
    assert ids[("concat-cpu-s1", "aliengo")] == "concat-cpu-s1-calibration-1.0.csv"
    assert ids[("film-cpu-s0", "go2")] == "film-cpu-s0-calibration.csv"
    at1 = rt.render_claims(tmp_path).split("### At 1.0 m/s")[1]
    assert "aliengo: EV multiplicative - additive +0.40 [+0.40, +0.40] (n 2 vs 2, p 0, Holm 0)" in at1
    assert "`dddddddddddd`" in at1
    block = rt.render(tmp_path)  # a table of its own, after the 2.0 m/s one
    assert block.index("### Critic calibration (") < block.index("### Critic calibration at 1.0 m/s")
    assert "| aliengo | 0.200 ± 0.000 (n=2) | 0.600 ± 0.000 (n=2) |" in block.split("at 1.0 m/s")[1]


def test_calibration_table_and_the_marked_block(tmp_path):
    block = rt.render(_runs(tmp_path))
    assert "| go2 | 0.373 | 0.333/0.859/0.531 | 1.768/1.943/0.771 |" in block  # paper film on Go2
    doc = tmp_path / "results.md"
    doc.write_text(f"intro\n{rt.BEGIN}\nold\n{rt.END}\noutro\n")
    rt.write_between_markers(doc, block)
    text = doc.read_text()
    assert text.startswith(f"intro\n{rt.BEGIN}\n### Descriptor") and text.endswith(f"{rt.END}\noutro\n")
    assert "old" not in text
    doc.write_text("no markers\n")
    with pytest.raises(SystemExit, match="no <!-- results-tables:begin -->"):
        rt.write_between_markers(doc, block)


ET_SCRIPT = SCRIPT.parent / "experiment_tables.py"
et_spec = importlib.util.spec_from_file_location("experiment_tables", ET_SCRIPT)
et = importlib.util.module_from_spec(et_spec)
et_spec.loader.exec_module(et)


def _fixed(critic, flip, rollout="r1"):
    return {"critic": critic, "variant": critic.split("-cpu")[0].lower(), "flip": flip, "rollout": rollout}


def test_fixed_rollout_rows_merge_per_samples_and_the_reference_row_is_read(tmp_path):
    cols = ["critic", "variant", "robot", "actor_variant", "flip", "cos_grad", "rollout", "samples"]
    path = tmp_path / "fixed-rollout-aliengo.csv"

    def rows(*critics, rollout="r1"):
        return [
            {**_fixed(c, f), "robot": "aliengo", "actor_variant": "film", "cos_grad": cos, "rollout": rollout}
            for c, f, cos in critics
        ]

    et.write_csv(path, et.merge_fixed_rows(path, rows(("MC", 0, 1), ("film-cpu-s0", 0.4, 0.3)), cols, "s1"), cols)
    # another store's rollout manifest (other id) of the same samples: merged; a critic's new row replaces its old
    merged = et.merge_fixed_rows(path, rows(("MC", 0, 1), ("ppo-cpu-s0", 0.5, 0.2), rollout="r2"), cols, "s1")
    assert [r["critic"] for r in merged] == ["MC", "film-cpu-s0", "ppo-cpu-s0"] and merged[0]["rollout"] == "r2"
    et.write_csv(path, merged, cols)
    # other samples (another machine's rollout): kept beside the reference rows, the sidecar names both
    merged = et.merge_fixed_rows(
        path, rows(("MC", 0, 1), ("film-cpu-s0", 0.43, 0.25), ("concat-cpu-s1", 0.3, 0.6), rollout="r3"), cols, "s2"
    )
    assert [(r["critic"], r["samples"]) for r in merged] == [
        ("MC", "s1"),
        ("film-cpu-s0", "s1"),
        ("ppo-cpu-s0", "s1"),
        ("MC", "s2"),
        ("film-cpu-s0", "s2"),
        ("concat-cpu-s1", "s2"),
    ]
    assert json.loads(path.with_suffix(".json").read_text()) == {
        "samples": "s1",
        "rollouts": ["r1", "r2"],
        "other_samples": {"s2": ["r3"]},
    }
    et.write_csv(path, merged, cols)
    # one row per critic, the reference one where there is one; the samples' effect from film, scored on both
    fixed = rt.load_fixed(tmp_path)
    assert [(r.critic, r.samples, r.reference) for r in fixed.itertuples()] == [
        ("MC", "s1", True),
        ("film-cpu-s0", "s1", True),
        ("ppo-cpu-s0", "s1", True),
        ("concat-cpu-s1", "s2", False),
    ]
    effect = rt.sample_effect(tmp_path)
    assert effect[["critic", "samples"]].values.tolist() == [["film-cpu-s0", "s2"]]
    assert effect["d_flip"].iloc[0] == pytest.approx(0.03) and effect["d_cos"].iloc[0] == pytest.approx(-0.05)
    note = " ".join(rt.sample_note(tmp_path, fixed))
    assert "`concat-cpu-s1` (aliengo)" in note and "Flip changes on aliengo (1 critics) by +0.030" in note
    assert "Cos by -0.050 (|Δ| at most 0.050)" in note
    assert "0.300 / 0.600 †" in "\n".join(rt.fixed_table(fixed))
    # a table written before the samples column: its rows are the sidecar's reference samples
    et.write_csv(path, [{c: r[c] for c in cols[:-1]} for r in merged[:3]], cols[:-1])
    assert set(rt.load_fixed(tmp_path)["samples"]) == {"s1"}


def test_curve_rows_keep_the_main_columns_to_five_digits():
    text = "iteration,env_steps,mean_reward,value_loss\n1,12288,0.123456789,3.0\n"
    rows = et.curve_rows(text)
    assert rows == [
        {**dict.fromkeys(et.CURVE_COLUMNS, ""), "iteration": "1", "env_steps": "12288", "mean_reward": "0.12346"}
    ]


def test_walk_table_checks_the_bar_and_finds_when_the_curriculum_opened(tmp_path):
    walk = {"vx_mean": 0.93, "vx_std": 0.18, "survival": 1.0, "verdict": "ok"}
    (tmp_path / "film-cpu-s0-walk.json").write_text(json.dumps([walk]))
    (tmp_path / "ppo-cpu-s0-walk.json").write_text(json.dumps([{**walk, "vx_mean": 0.79}]))  # below 0.8: no
    (tmp_path / "film-cpu-s0-curve.csv").write_text("iteration,curriculum.vx_max\n1,1.0\n2,1.0\n3,1.5\n4,2.0\n")
    (tmp_path / "film-cpu-s0-eval.csv").write_text(  # the template at 2.0 m/s: the descriptor row, not full's
        EVAL_HEAD + "go2,full,2.0,0.0,1.1,0.3,0.5,ok\ngo2,descriptor,2.5,0.0,0.7,0.3,0.2,falls\n"
        "go2,descriptor,2.0,0.0,1.4567,0.3,0.65625,falls\naliengo,descriptor,2.0,0.324,1.6,0.6,0.0,falls\n"
    )
    lines = rt.walk_table(tmp_path)
    assert lines[2] == "| `ppo-cpu-s0` | 0.79 ± 0.18 | 1.000 | ok | **no** | - | - | - |"  # paper order: ppo first
    assert lines[3] == "| `film-cpu-s0` | 0.93 ± 0.18 | 1.000 | ok | yes | 3 | 2 m/s | 1.46 / 0.656 |"


class _Store:
    """``read_manifest`` / ``weights_omitted`` of a store holding ``runs`` (name -> its weights were left out)."""

    def __init__(self, runs: dict[str, bool]):
        self.runs = runs

    def read_manifest(self, spec):
        from morfic_cli.errors import ArtifactNotFoundError

        if spec[len("runs/") :] not in self.runs:
            raise ArtifactNotFoundError(spec)
        return spec

    def weights_omitted(self, spec):
        return self.runs[spec[len("runs/") :]]


def test_seed0_critics_with_weights_are_rescored_on_other_samples(tmp_path):
    cols = ["critic", "samples"]
    (tmp_path / "fixed-rollout-aliengo.json").write_text(json.dumps({"samples": "s1", "rollouts": []}))
    et.write_csv(
        tmp_path / "fixed-rollout-aliengo.csv",
        [
            {"critic": c, "samples": s}
            for c, s in (
                ("MC", "s1"),
                ("film-cpu-s0", "s1"),
                ("ppo-cpu-s0", "s1"),
                ("adaln-cpu-s0", "s1"),
                ("hyper-cpu-s0", "s1"),
                ("film-cpu-s1", "s1"),
                ("MC", "s2"),
                ("concat-cpu-s1", "s2"),
                ("film-cpu-s0", "s2"),
            )
        ],
        cols,
    )
    for run in ("film", "ppo", "adaln", "hyper", "actor-only"):
        (tmp_path / f"{run}-cpu-s0-artifacts.json").write_text("{}")
    (tmp_path / "film-cpu-s1-artifacts.json").write_text("{}")
    # film: already on s2; adaln: weights left out; hyper: not in the store; actor-only: no reference row;
    # film-cpu-s1: not seed 0. Only ppo is scored again.
    store = _Store(
        {
            "film-cpu-s0": False,
            "ppo-cpu-s0": False,
            "adaln-cpu-s0": True,
            "actor-only-cpu-s0": False,
            "film-cpu-s1": False,
        }
    )
    assert et.seed0_to_rescore(store, tmp_path, {"aliengo": "s2"}) == ["ppo-cpu-s0"]
    # a critic scored on the reference samples: nothing to measure
    assert et.seed0_to_rescore(store, tmp_path, {"aliengo": "s1"}) == []


def test_bundle_table_sizes_every_tar_from_the_files(tmp_path):
    """Sizes in MiB from the files themselves: 3 + 1.5 MiB seed-0 weights, 0.75 MiB a seed's weights, 0.25 MiB
    results -> 5.5 in all."""
    bundles = tmp_path / "bundles"
    (bundles / "results").mkdir(parents=True)
    (bundles / "weights").mkdir()
    (bundles / "film-cpu-s0.tar").write_bytes(b"\0" * (3 * rt.MIB))
    (bundles / "ppo-cpu-s0.tar").write_bytes(b"\0" * (3 * rt.MIB // 2))
    (bundles / "weights" / "film-cpu-s1.tar").write_bytes(b"\0" * (3 * rt.MIB // 4))
    (bundles / "results" / "film-cpu-s1.tar").write_bytes(b"\0" * (rt.MIB // 4))
    (bundles / "notes.txt").write_text("not a bundle")
    lines = rt.bundle_table(bundles)
    assert lines[2] == f"| `{(bundles / 'film-cpu-s0.tar').as_posix()}` | weights-only | 3.0 |"
    assert lines[3] == f"| `{(bundles / 'ppo-cpu-s0.tar').as_posix()}` | weights-only | 1.5 |"
    assert lines[4] == f"| `{(bundles / 'weights' / 'film-cpu-s1.tar').as_posix()}` | weights-only (seed >= 1) | 0.8 |"
    assert lines[5] == f"| `{(bundles / 'results' / 'film-cpu-s1.tar').as_posix()}` | results only | 0.2 |"
    assert lines[-1] == "| 4 tars | weights-only 4.5, weights-only (seed >= 1) 0.8, results only 0.2 | **5.5** |"
    assert rt.bundle_table(tmp_path / "none") == [f"No bundle under {tmp_path / 'none'}."]


def test_the_1_0_diagnosis_is_the_papers_protocol_at_one_metre_per_second(tmp_path):
    # written out by hand: the paper's diagnosis (every robot in the paper's order, descriptor mode, 64 envs x 800
    # steps, eps 0.05) with the command alone changed
    from morfic_cli.diagnostics.samples import diagnose_config
    from morfic_cli.store import Store

    pipe = et.one_run_pipeline(Store(tmp_path / "store"), "concat", 1, "runs/concat-cpu-s1")
    paper = {
        "robots": ("go2", "go1", "a1", "aliengo", "b1", "mini_cheetah", "anymal_c"),
        "mode": "descriptor",
        "command_vx": 2.0,
        "num_envs": 64,
        "steps": 800,
        "seed": 0,
        "trunc_eps": 0.05,
        "sigma_eps": 1e-08,
    }
    assert diagnose_config(pipe.diagnose_cfg(pipe.cfg.robots)) == paper
    assert diagnose_config(et.trained_regime_diagnose_cfg(pipe)) == {**paper, "command_vx": 1.0}


def test_the_queue_evaluates_at_one_metre_per_second_as_the_seed0_runs_were():
    # the config of the seed-0 runs' eval-1.0 manifests (e.g. 5ab3f74638d4, `morfic eval runs/film-cpu-s0
    # --command-vx 1.0`), written out by hand: the queue's 1.0 m/s eval must have the same content address
    from morfic_cli.evaluation.protocol import eval_config
    from morfic_cli.pipeline import _json

    assert _json(eval_config("runs/film-cpu-s1", et.trained_regime_cfg("film"))) == {
        "spec": "runs/film-cpu-s1",
        "robots": ["go2", "a1", "aliengo", "anymal_c", "b1", "go1", "mini_cheetah"],
        "modes": ["descriptor"],
        "command_vx": [1.0],
        "num_envs": 64,
        "steps": 500,
        "seed": 0,
        "scene_envs": 4,
    }


def test_a_run_retrained_under_its_name_replaces_the_lost_runs_rows_unless_its_weights_are_the_same(tmp_path):
    cols = ["critic", "flip", "checkpoint", "rollout", "samples"]
    path = tmp_path / "fixed-rollout-aliengo.csv"

    def row(critic, flip, checkpoint):
        return {"critic": critic, "flip": flip, "checkpoint": checkpoint, "rollout": "r"}

    first = [row("MC", 0, ""), row("film-cpu-s1", 0.40, "lost"), row("ppo-cpu-s0", 0.35, "p0")]
    et.write_csv(path, et.merge_fixed_rows(path, first, cols, "amd"), cols)
    # film-cpu-s1 retrained (checkpoint "new", other weights), scored on another CPU's samples: the lost run's
    # reference row goes, ppo's stays
    merged = et.merge_fixed_rows(path, [row("MC", 0, ""), row("film-cpu-s1", 0.45, "new")], cols, "intel")
    assert [(r["critic"], r["checkpoint"], r["samples"]) for r in merged] == [
        ("MC", "", "amd"),
        ("ppo-cpu-s0", "p0", "amd"),
        ("MC", "", "intel"),
        ("film-cpu-s1", "new", "intel"),
    ]
    # ppo-cpu-s0 retrained bit for bit (same weights under checkpoint "p0b"): its reference row is kept beside the new
    merged = et.merge_fixed_rows(
        path, [row("MC", 0, ""), row("ppo-cpu-s0", 0.36, "p0b")], cols, "intel", same_weights=frozenset({"p0"})
    )
    assert ("ppo-cpu-s0", "p0", "amd") in [(r["critic"], r["checkpoint"], r["samples"]) for r in merged]


def test_claim_c_is_judged_at_1_m_s_from_the_fixed_rollout_1_0_files(tmp_path):
    """Two seeds alike (a point interval) at each command: film beats ppo at 1.0 m/s, loses at 2.0 m/s on AlienGo."""
    _runs(tmp_path)
    (tmp_path / "film-cpu-s0-eval-1.0.csv").write_text(EVAL_HEAD + "aliengo,descriptor,1.0,0.324,0.9,0.1,1.0,walks\n")
    cols = ["critic", "variant", "robot", "actor", "actor_variant", "flip", "cos_grad", "command_vx", "rollout"]
    # (flip, cos) per variant: 2.0 m/s film 0.40/0.30, ppo 0.45/0.20; 1.0 m/s film 0.20/0.70, ppo 0.30/0.50
    for vx, values in (
        (2.0, {"film": (0.40, 0.30), "ppo": (0.45, 0.20)}),
        (1.0, {"film": (0.20, 0.70), "ppo": (0.30, 0.50)}),
    ):
        rows = [{"critic": "MC", "variant": "mc", "flip": 0.0, "cos_grad": 1.0}]
        rows += [
            {"critic": f"{v}-cpu-s{s}", "variant": v, "flip": f, "cos_grad": c}
            for v, (f, c) in values.items()
            for s in (0, 1)
        ]
        rows = [
            {**r, "robot": "aliengo", "actor": "film-cpu-s0", "actor_variant": "film", "command_vx": vx, "rollout": "r"}
            for r in rows
        ]
        et.write_csv(et.fixed_rollout_path(tmp_path, "aliengo", vx), rows, cols)
    assert [p.name for p in sorted(tmp_path.glob("fixed-rollout-*.csv"))] == [
        "fixed-rollout-1.0-aliengo.csv",
        "fixed-rollout-aliengo.csv",
    ]
    (tmp_path / "film-cpu-s1-artifacts.json").write_text(
        json.dumps({"fixed_rollout": {"aliengo": "a" * 64}, et.fixed_rollout_key(1.0): {"aliengo": "b" * 64}})
    )
    fixed = rt.load_fixed(tmp_path)  # one row per command, robot and critic: MC and four critics at each command
    assert sorted(fixed.groupby("command_vx").size().to_dict().items()) == [(1.0, 5), (2.0, 5)]
    # each command's table pools its own seeds; the paper's columns at 2.0 only
    at2, at1 = rt.fixed_table(fixed, 2.0), rt.fixed_table(fixed, 1.0)
    assert at2[0] == "| critic | aliengo Flip / Cos | paper aliengo |"
    assert "| `film` (n=2) | 0.400 ± 0.000 / 0.300 ± 0.000 (n=2) | 0.255 / 0.366 |" in at2
    assert at1[0] == "| critic | aliengo Flip / Cos |"
    assert "| `film` (n=2) | 0.200 ± 0.000 / 0.700 ± 0.000 (n=2) |" in at1
    block = rt.render(tmp_path)
    assert block.index("### Fixed rollout (") < block.index("### Fixed rollout at 1.0 m/s")
    # each row's id from its command's entry of artifacts.json, else its command's file
    _, _, rows = rt.claim_rows(tmp_path)
    ids = {(r["critic"], r["command_vx"]): r["artifact"] for r in rows}
    assert ids[("film-cpu-s1", 2.0)] == "a" * 64 and ids[("film-cpu-s1", 1.0)] == "b" * 64
    assert ids[("ppo-cpu-s1", 1.0)] == "fixed-rollout-1.0-aliengo.csv"
    text = rt.render_claims(tmp_path)
    on2, on1 = text.split("### At 2.0 m/s")[1].split("### At 1.0 m/s")
    # 2.0: 0.40 - 0.45 = -0.05 Flip, 0.30 - 0.20 = +0.10 Cos; 1.0: 0.20 - 0.30 = -0.10, 0.70 - 0.50 = +0.20
    assert "aliengo: film - ppo Flip -0.050 [-0.050, -0.050] (n 2 vs 2, p 0, Holm 0); film - ppo Cos +0.100" in on2
    assert "aliengo: film - ppo Flip -0.100 [-0.100, -0.100] (n 2 vs 2, p 0, Holm 0); film - ppo Cos +0.200" in on1
    assert "`bbbbbbbbbbbb`" in on1 and "aaaaaaaaaaaa" not in on1


def test_the_1_0_fixed_rollout_is_the_papers_analysis_at_one_metre_per_second_and_its_flags_go_alone(tmp_path):
    from morfic_cli.diagnostics.samples import diagnose_config
    from morfic_cli.store import Store

    pipe = et.one_run_pipeline(Store(tmp_path / "store"), "concat", 1, "runs/concat-cpu-s1")
    # written out by hand: the paper's analysis on one robot (64 envs x 800 steps, eps 0.05), the command changed
    paper = {
        "robots": ("aliengo",),
        "mode": "descriptor",
        "command_vx": 2.0,
        "num_envs": 64,
        "steps": 800,
        "seed": 0,
        "trunc_eps": 0.05,
        "sigma_eps": 1e-08,
    }
    assert diagnose_config(pipe.diagnose_cfg(("aliengo",))) == paper
    assert diagnose_config(pipe.diagnose_cfg(("aliengo",), 1.0)) == {**paper, "command_vx": 1.0}
    assert et.fixed_rollout_path(tmp_path, "b1").name == "fixed-rollout-b1.csv"
    assert et.fixed_rollout_path(tmp_path, "b1", 1.0).name == "fixed-rollout-1.0-b1.csv"
    assert (et.fixed_rollout_key(), et.fixed_rollout_key(1.0)) == ("fixed_rollout", "fixed_rollout-1.0")
    for argv in (
        ["--fixed-rollout-only", "--fixed-rollout-1.0-only"],
        ["--diagnosis-1.0-only", "--rescore"],
        ["--rescore"],
        ["--run-missing", "--rescore"],
    ):
        with pytest.raises(SystemExit) as exit_:
            et.main(["concat-cpu-s1", *argv, "--store", str(tmp_path / "store")])
        assert exit_.value.code == 2, argv


def test_the_answer_and_the_readme_headline_are_written_from_the_verdicts(tmp_path):
    """Two seeds alike of film and ppo on AlienGo: film keeps 0.00 against ppo's 0.51, exact (zero spread): (b)'s
    one comparison with a test is significant against the claim -> partly reversed; the rest cannot tell."""
    _runs(tmp_path)
    for run in ("film", "ppo"):
        (tmp_path / f"{run}-cpu-s1-eval.csv").write_text((tmp_path / f"{run}-cpu-s0-eval.csv").read_text())
    answer = rt.render_answer(tmp_path)
    assert "(2 variants x 2 seeds)" in answer
    assert "**At 2.0 m/s (the paper's command): (b) partly reversed; (a), (c), (d) and (e) cannot tell.**" in answer
    assert (
        "| (b) MorFiC-F transfers better than ppo, actor-only, concat | **partly reversed** | "
        "AlienGo film - ppo -0.51 [-0.51, -0.51] (Holm p 0, against the claim) at 2.0 m/s |" in answer
    )
    assert "none: its test is over the robots, and seeds add no robots" in answer
    head = rt.render_headline(tmp_path)
    assert head.startswith(
        "- The paper's five claims on the trained policies (2 variants x 2 seeds, the `cpu` "
        "preset), read with Holm-corrected Welch and t-contrast tests over seeds: at 2.0 m/s (b) "
        "partly reversed; (a), (c), (d) and (e) cannot tell."
    )
    readme, doc = tmp_path / "README.md", tmp_path / "results.md"
    readme.write_text(f"# x\n\n## What the experiment found\n\n{rt.HEADLINE_BEGIN}\nold\n{rt.HEADLINE_END}\nkept\n")
    doc.write_text(
        f"{rt.BEGIN}\n{rt.END}\n{rt.CLAIMS_BEGIN}\n{rt.CLAIMS_END}\n{rt.WALK_BEGIN}\n{rt.WALK_END}\n"
        f"{rt.BUNDLES_BEGIN}\n{rt.BUNDLES_END}\n## The answer\n{rt.ANSWER_BEGIN}\nold\n{rt.ANSWER_END}\n"
    )
    assert (
        rt.main(
            [
                "--results",
                str(tmp_path),
                "--write",
                str(doc),
                "--readme",
                str(readme),
                "--bundles",
                str(tmp_path / "none"),
            ]
        )
        == 0
    )
    assert "old" not in readme.read_text() and readme.read_text().endswith(f"{rt.HEADLINE_END}\nkept\n")
    assert head in readme.read_text() and answer in doc.read_text()


def test_the_shipped_answer_and_headline_are_current():
    """docs/results.md's answer and README's headline are what the script makes of docs/results/ now."""
    root = SCRIPT.parents[1]
    results = root / "docs" / "results"
    assert rt.render_answer(results) in (root / "docs" / "results.md").read_text()
    assert rt.render_headline(results) in (root / "README.md").read_text()
    assert rt.goal_block(results) in (root / "docs" / "results.md").read_text()  # issue 58's goal section


GOAL_HEAD = "robot,mode,command_vx,d,vx_mean,vx_std,survival,verdict\n"


def _still(tmp_path: Path) -> Path:
    """genloco s0 stands still on AlienGo, Cheetah and ANYmal-C at 2.0 m/s; film s0 walks there (descriptor mode)."""
    (tmp_path / "genloco-cpu-s0-eval.csv").write_text(
        GOAL_HEAD
        + "aliengo,descriptor,2.0,0.324,0.10,0.11,0.531,stands still\n"
        + "mini_cheetah,descriptor,2.0,0.416,0.01,0.04,0.969,stands still\n"
        + "anymal_c,descriptor,2.0,0.353,0.10,0.09,0.594,stands still\n"
    )
    (tmp_path / "film-cpu-s0-eval.csv").write_text(
        GOAL_HEAD
        + "aliengo,descriptor,2.0,0.324,0.84,0.5,0.0,falls\n"
        + "mini_cheetah,descriptor,2.0,0.416,1.96,0.3,0.984,drags feet\n"
        + "anymal_c,descriptor,2.0,0.353,0.35,0.2,0.0,falls\n"
        + "go2,full,2.0,0.0,1.5,0.3,0.9,ok\n"
    )
    return tmp_path


def test_a_baseline_that_stands_still_is_said_to_and_one_seed_has_no_interval(tmp_path):
    ev = rt.load_evals(_still(tmp_path))
    text = "\n".join(rt.architecture_text(ev))
    assert "- **URMA** (`urma`): not trained yet" in text and "- **BodyTransformer** (`bot`): not trained yet" in text
    assert "(`genloco`, s0; one seed: no interval). It stands still." in text
    assert "descriptor mode: stands still on 3 of 3 robots" in text
    # AlienGo: v_x 0.10 - 0.84 = -0.74, S 0.531 - 0.000 = +0.531; the difference only (one seed each)
    assert "AlienGo v_x 0.10 vs 0.84: -0.74, S 0.531 vs 0.000: +0.531 (stands still)" in text
    assert "Cheetah v_x 0.01 vs 1.96: -1.95, S 0.969 vs 0.984: -0.015 (stands still)" in text
    assert "2.0 m/s, full mode: no rows of `genloco` yet." in text
    assert "[" not in text  # no interval anywhere at one seed


def test_the_architecture_text_reads_films_full_mode_goal_eval_at_1_m_s(tmp_path):
    """film's full-mode 1.0 m/s rows live in <run>-eval-1.0-full.csv (the goal's eval): the block compares with them."""
    _still(tmp_path)
    (tmp_path / "genloco-cpu-s0-eval-1.0.csv").write_text(GOAL_HEAD + "aliengo,full,1.0,0.324,0.10,0.1,0.0,falls\n")
    (tmp_path / "film-cpu-s0-eval-1.0-full.csv").write_text(GOAL_HEAD + "aliengo,full,1.0,0.324,0.95,0.1,0.5,ok\n")
    text = "\n".join(rt.architecture_text(rt.load_evals(tmp_path)))
    assert "1.0 m/s, full mode: no rows of `film` yet." in text  # the runs' own evals alone lack film's rows
    block = rt.external_block(tmp_path)
    assert "1.0 m/s, full mode, against `film`: AlienGo v_x 0.10 vs 0.95: -0.85, S 0.000 vs 0.500: -0.500" in block


def test_two_seeds_a_side_give_the_welch_interval(tmp_path):
    _still(tmp_path)
    for run, vx in (("genloco", 0.30), ("film", 1.24)):  # AlienGo v_x: genloco 0.10, 0.30; film 0.84, 1.24
        (tmp_path / f"{run}-cpu-s1-eval.csv").write_text(GOAL_HEAD + f"aliengo,descriptor,2.0,0.324,{vx},0.1,0.0,x\n")
    text = "\n".join(rt.architecture_text(rt.load_evals(tmp_path)))
    # 0.20 - 1.04 = -0.84 with its t interval over 2 vs 2 seeds, Holm over genloco's six comparisons at 2.0 m/s
    assert "AlienGo v_x 0.20 vs 1.04: -0.84 [" in text and "(n 2 vs 2, p " in text and ", Holm " in text


def test_external_block_has_the_papers_group_ours_and_compute(tmp_path):
    (_still(tmp_path) / "genloco-cpu-s0-curve.csv").write_text(
        "iteration,env_steps,wall_time_s\n1,12288,5.0\n1000,12288000,5469.2\n"
    )
    text = rt.external_block(tmp_path, params=lambda v: (1000, 2000))
    assert "| Embodiment Scaling (paper) | 1.23 ± 0.06 / 0.906 |" in text  # the paper's Go2 cell, 2.0 m/s
    assert "| GenLoco `genloco` (s0) | - | - | - | 0.10 ± 0.11 / 0.531 (stands still) |" in text
    assert "| URMA `urma`: not trained yet |" in text
    assert "not retrainable here" in text  # Embodiment Scaling's one-line reason
    # 5469.2 s over 1000 iterations: 1.52 h, 5.47 s/iteration
    row = "| GenLoco `genloco` | 1,000 / 2,000 | s0 | 12.3M | 1,000 | 1.52 h | 5.47 | 53.3 (200M); 213.5 (800M) |"
    assert row in text


def test_goal_block_without_actuation_runs_says_how_and_judges_film(tmp_path):
    text = rt.goal_block(_still(tmp_path))
    assert "`morfic train --variant film-act --preset cpu`" in text
    assert "**Full mode at 1.0 m/s:** no rows yet." in text
    assert "| Go2 | 1.50 / 0.900 / ok / **meets** |" in text  # exactly at 2.0 m/s's bars
    assert "| clears the bar | 1 of 7 |" in text
    assert "robots meeting the goal (both commands, every seed): **0 of 7**; no full-mode rows at 1.0 m/s yet" in text


TERM_HEAD = "robot,mode,command_vx,term,envs\n"


def test_goal_and_external_blocks_say_what_ended_the_failed_episodes_where_counts_exist(tmp_path):
    _still(tmp_path)
    (tmp_path / "film-cpu-s0-terminations.csv").write_text(
        TERM_HEAD + "go2,full,2.0,illegal_contact,4\ngo2,full,2.0,excessive_tilt,6\ngo2,full,2.0,nonfinite,0\n"
        "aliengo,descriptor,2.0,illegal_contact,64\naliengo,descriptor,2.0,base_too_low,0\n"
    )
    (tmp_path / "genloco-cpu-s0-terminations-1.0.csv").write_text(
        TERM_HEAD + "anymal_c,descriptor,1.0,base_too_low,33\nanymal_c,descriptor,1.0,illegal_contact,0\n"
    )
    (tmp_path / "genloco-cpu-s1-terminations-1.0.csv").write_text(
        TERM_HEAD + "anymal_c,descriptor,1.0,base_too_low,7\nanymal_c,descriptor,1.0,illegal_contact,1\n"
    )
    goal = rt.goal_block(tmp_path)
    assert "**What ended the failed episodes: full mode at 2.0 m/s.**" in goal
    assert "| Go2 | excessive_tilt 6, illegal_contact 4 |" in goal and "| B1 | - |" in goal
    assert "**What ended the failed episodes at 1.0 m/s:** no counts in full mode yet." in goal
    assert rt.NO_COUNTS not in goal
    ext = rt.external_block(tmp_path, params=lambda v: (1, 1))
    # ANYmal-C at 1.0 m/s over s0 and s1: base_too_low 33 + 7 = 40, illegal_contact 0 + 1 = 1
    assert "| GenLoco `genloco` (s0, s1), descriptor, 1.0 m/s | - | - | base_too_low 40, illegal_contact 1 |" in ext
    assert "| MorFiC-F `film` (s0), descriptor, 2.0 m/s | illegal_contact 64 | - | - |" in ext
    assert "full, 2.0 m/s" not in ext  # film's full-mode counts are on Go2 only, not on these three robots


def test_without_termination_files_both_blocks_say_the_counts_come_with_the_next_evaluations(tmp_path):
    _still(tmp_path)
    assert f"**What ended the failed episodes:** {rt.NO_COUNTS}" in rt.goal_block(tmp_path)
    assert "No termination counts in these runs' evals yet" in rt.external_block(tmp_path, params=lambda v: (1, 1))
    assert "envs" not in rt.load_terminations(tmp_path).columns


def test_goal_block_reads_films_full_mode_1_0_eval_and_only_the_goal_block_is_rewritten(tmp_path):
    _still(tmp_path)
    # film s0's goal eval (scripts/experiment_tables.py: <run>-eval-1.0-full.csv): Go2 at the 1.0 m/s bars exactly,
    # Go1 drags its feet; its counts beside it
    (tmp_path / "film-cpu-s0-eval-1.0-full.csv").write_text(
        GOAL_HEAD + "go2,full,1.0,0.0,0.9,0.1,0.95,ok\ngo1,full,1.0,0.215,1.2,0.1,1.0,drags feet\n"
    )
    (tmp_path / "film-cpu-s0-terminations-1.0-full.csv").write_text(TERM_HEAD + "go2,full,1.0,excessive_tilt,3\n")
    assert rt.goal_kinds() == ("eval-1.0-full",) and rt.goal_kinds("terminations") == ("terminations-1.0-full",)
    text = rt.goal_block(tmp_path)
    assert "**Full mode at 1.0 m/s:** no rows yet" not in text
    assert "**Against issue 58's goal: full mode at 1.0 m/s.**" in text
    assert "| Go2 | 0.90 / 0.950 / ok / **meets** |" in text and "| Go1 | 1.20 / 1.000 / drags feet / misses |" in text
    assert "| clears the bar | 1 of 7 |" in text
    assert "| Go2 | excessive_tilt 3 |" in text  # what ended film's failed episodes at 1.0 m/s, full mode
    assert "`<run>-eval-1.0-full.csv`, made and copied by `scripts/experiment_tables.py RUN --goal-evals-only`" in text
    # Go2 meets at both commands (1.5 / 0.9 at 2.0 m/s), the only robot with rows at both
    assert "robots meeting the goal (both commands, every seed): **1 of 7** (Go2)." in text
    ev = rt.load_evals(tmp_path)  # the other blocks read the runs' own evals alone
    assert ev[(ev["mode"] == "full") & (ev["command_vx"] == 1.0)].empty and not ev[ev["command_vx"] == 2.0].empty
    doc = tmp_path / "doc.md"
    doc.write_text(f"hand\n{rt.GOAL_BEGIN}\nold\n{rt.GOAL_END}\n{rt.BEGIN}\nold tables\n{rt.END}\nhand\n")
    assert rt.main(["--results", str(tmp_path), "--write", str(doc), "--only", "goal"]) == 0
    assert doc.read_text() == f"hand\n{rt.GOAL_BEGIN}\n{text}{rt.GOAL_END}\n{rt.BEGIN}\nold tables\n{rt.END}\nhand\n"
    with pytest.raises(SystemExit):
        rt.main(["--results", str(tmp_path), "--only", "goal"])  # --only without --write
