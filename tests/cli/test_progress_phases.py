"""StepBar.phase: a command with stages that count different work shows one completed bar per stage."""

from morfic_cli.cli._progress import StepBar


def test_phases_replace_the_empty_bar_and_complete_each_stage():
    with StepBar("critic-study", 0, False) as bar:
        bar.phase("rollouts", 3)
        bar.step()
        bar.phase("fits", 2)  # the rollouts stage is shown complete though only 1 of 3 was counted
        bar.step()
        bar.step()
        shown = [(t.description, t.completed, t.total) for t in bar.bar.tasks]
    assert shown == [("rollouts", 3, 3), ("fits", 2, 2)]


def test_quiet_phases_do_nothing():
    with StepBar("critic-study", 0, True) as bar:
        bar.phase("rollouts", 3)
        bar.step()
        assert bar.bar is None


def test_eval_video_rendering_is_a_phase_that_counts_frames(run_cli, smoke_runs, tmp_path, monkeypatch, gl_backend):
    """`eval --video` renders for minutes in software GL after the rollouts' bar is full: a bar of its own, in frames.

    4 steps rendered every 2nd step = 2 frames; the rollouts' bar (4 steps) is shown complete above it.
    """
    smoke_runs.store(tmp_path / "store")
    monkeypatch.setenv("MORFIC_STORE", str(tmp_path / "store"))
    code, _, err = run_cli(
        "eval",
        "runs/film-s0",
        "--robots",
        "go2",
        "--envs",
        "2",
        "--steps",
        "4",
        "--command-vx",
        "1.0",
        "--video",
        "--format",
        "json",
    )
    assert code == 0, err
    lines = [" ".join(line.split()) for line in err.splitlines()]
    assert any(line.startswith("eval go2 descriptor vx=1") and line.endswith("4/4 0:00:00") for line in lines), err
    videos = [line for line in lines if line.startswith("eval videos go2-descriptor-vx1")]
    assert videos and videos[-1].split()[-2] == "2/2", err
