"""The eval figure's curves, computed by hand on a 4-step x 3-env rollout."""

from __future__ import annotations

import numpy as np

from morfic_cli.evaluation.figures import rollout_figure, running_mean, speed_survival, verdict_line
from morfic_cli.evaluation.metrics import env_outcomes, transfer_metrics


def test_speed_survival_curves_by_hand():
    vx = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 5.0], [1.0, 4.0, 9.0], [2.0, 4.0, 9.0]], dtype=np.float32)
    terminated = np.zeros((4, 3), bool)
    terminated[1, 2] = True  # env 2 falls at step 1: alive at step 0 only
    terminated[3, 0] = True  # env 0 falls at the last step
    c = speed_survival(vx, terminated, dt=0.5)
    np.testing.assert_allclose(c["t"], [0.5, 1.0, 1.5, 2.0])
    np.testing.assert_allclose(c["mean"], [2.0, 1.5, 2.5, 4.0])  # alive envs: {0,1,2}, {0,1}, {0,1}, {1}
    np.testing.assert_allclose(c["survival"], [1.0, 2 / 3, 2 / 3, 1 / 3])
    np.testing.assert_allclose(sorted(c["fall_t"]), [1.0, 2.0])
    # the band: 10th and 90th percentiles (linear interpolation) of the alive envs
    np.testing.assert_allclose(c["low"][0], 1.2)
    np.testing.assert_allclose(c["high"][1], 1.9)


def test_no_env_alive_leaves_the_speed_undefined_and_the_figure_draws():
    vx = np.ones((3, 2), np.float32)
    terminated = np.array([[True, True], [False, False], [False, False]])
    c = speed_survival(vx, terminated, dt=0.02)
    assert np.isnan(c["mean"]).all() and c["survival"].tolist() == [0.0, 0.0, 0.0]
    png, pdf = rollout_figure(vx, terminated, 0.02, 2.0, "b1, descriptor mode, command 2 m/s")
    assert png.startswith(b"\x89PNG") and pdf.startswith(b"%PDF")


def test_each_envs_running_mean_ends_at_the_mean_the_verdict_uses():
    slip = np.array([[0.1, 0.4], [0.3, 0.4], [0.5, 0.1]])
    alive = np.array([[True, True], [True, True], [True, False]])  # env 1 fell at step 2
    r = running_mean(slip, alive)
    np.testing.assert_allclose(r[:, 0], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(r[:, 1], [0.4, 0.4, 0.4])  # frozen after its fall
    assert np.isnan(running_mean(slip, np.zeros_like(alive))).all()


def test_the_verdict_line_is_the_tables_verdict_with_each_failure_counted():
    # 4 envs, 3 steps at 1 m/s: env 0 fine, env 1 drags its feet, env 2 stands still, env 3 falls
    vx = np.array([[1.0, 1.0, 0.0, 1.0]] * 3)
    terminated = np.zeros((3, 4), bool)
    terminated[1, 3] = True
    slip = np.array([[0.1, 0.5, 0.0, 0.1]] * 3)
    kw = {"tilt": np.zeros((3, 4)), "height_ratio": np.ones((3, 4)), "foot_slip": slip}
    outcomes = env_outcomes(vx, terminated, 1.0, **kw)
    assert outcomes.tolist() == ["ok", "drags feet", "stands still", "falls"]
    m = transfer_metrics(vx, terminated, 1.0, 0.02, **kw)
    assert m.valid_fraction == 0.25 and m.verdict == "falls"  # a tie: the first failure class in order
    assert verdict_line(outcomes, m.verdict) == (
        "verdict: falls \u2013 valid 1/4 (falls 1, stands still 1, drags feet 1)",
        False,
    )
    assert verdict_line(outcomes) == verdict_line(outcomes, m.verdict)
    assert verdict_line(np.array(["ok", "ok", "drags feet"])) == ("verdict: ok \u2013 valid 2/3 (drags feet 1)", True)
    png, pdf = rollout_figure(vx, terminated, 0.02, 1.0, "t", foot_slip=slip, outcomes=outcomes, verdict=m.verdict)
    assert png.startswith(b"\x89PNG") and pdf.startswith(b"%PDF")


def test_a_left_out_speed_figure_is_drawn_from_the_eval_row(tmp_path):
    """A rollout imported results-only has no speed figure: `eval --out` (and the report) draw it from eval.csv."""
    import csv
    import io

    from morfic_cli.evaluation.figures import figure_or_table, table_figure, write_figures
    from morfic_cli.store import Store

    src = Store(tmp_path / "src")
    ckpt = src.put_manifest("checkpoint", config={"variant": "film"}, files={"model.pt": b"w", "curve.csv": b"it\n1"})
    src.set_ref("runs/x", ckpt)
    rollout = src.put_manifest(
        "rollout",
        config={"robot": "go1"},
        inputs={"checkpoint": ckpt},
        files={"rollout.mcap": b"log", "speed.png": b"png", "speed.pdf": b"pdf"},
    )
    table = (
        b"robot,mode,command_vx,vx_mean,vx_std,vx_peak_1s_mean,vx_peak_1s_std,survival,valid_fraction,verdict,"
        b"num_envs\ngo1,descriptor,2.0,1.5,0.25,1.75,0.5,0.75,0.5,ok,8\n"
    )
    ev = src.put_manifest(
        "eval",
        inputs={"checkpoint": ckpt, "rollout/go1/descriptor/vx2": rollout},
        files={"eval.csv": table},
        meta={"run": "x"},
    )
    src.set_ref("evals/x", ev)
    assert figure_or_table(src, rollout, None, "t") == (b"png", b"pdf")  # stored: read back as it is
    dst = Store(tmp_path / "dst")
    dst.import_tar(src.export_tar(["runs/x"], tmp_path / "x.tar", results_only=True).path)
    assert set(dst.omitted_files(dst.read_manifest(rollout))) == {"rollout.mcap", "speed.png", "speed.pdf"}
    assert figure_or_table(dst, rollout, None, "t") is None  # left out, and no row to draw it from
    row = next(csv.DictReader(io.StringIO(table.decode())))
    drawn = table_figure(row, "x on go1, descriptor mode, command 2 m/s")
    assert drawn[0].startswith(b"\x89PNG") and drawn[1].startswith(b"%PDF")
    paths = write_figures(dst, ev, tmp_path)
    assert [p.name for p in paths] == ["go1-descriptor-vx2-speed.png", "go1-descriptor-vx2-speed.pdf"]
    assert [p.read_bytes() for p in paths] == list(drawn)
    (tmp_path / "out").mkdir()
    assert [p.read_bytes() for p in write_figures(src, ev, tmp_path / "out")] == [b"png", b"pdf"]
