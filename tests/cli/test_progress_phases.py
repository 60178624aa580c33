"""StepBar: one completed bar per stage on a terminal; plain lines, paced, in a log (not a terminal)."""

import io
from types import SimpleNamespace

from rich.console import Console

from morfic_cli.cli import _progress
from morfic_cli.cli._progress import LogPace, StepBar


def _console(terminal: bool) -> Console:
    return Console(file=io.StringIO(), force_terminal=terminal, emoji=False)


def test_phases_replace_the_empty_bar_and_complete_each_stage():
    with StepBar("critic-study", 0, False, console=_console(terminal=True)) as bar:
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
        assert bar.bar is None and bar.lines is None


def test_a_log_gets_a_line_a_phase_start_each_5_percent_and_30_s_and_a_last_line(monkeypatch):
    """A fake clock: rollouts 100 steps of 1 s, fits 4 of 40 steps of 20 s, scoring 1 of 3 steps of 5 s.

    rollouts: every 5 steps is due by the 5 %, but only each 30 s passes the time limit: 30, 60, 90, left at 1 s a
    step = 70, 40, 10 s. fits: 5 % of 40 = 2 steps, 40 s apart: after 40 s 2/40 -> 40 / 2 * 38 = 760 s left
    (0:12:40), after 80 s 4/40 -> 80 / 4 * 36 = 720 s (0:12:00); the next phase shows it complete (40/40, 80 s).
    scoring: 1 of 3 after 5 s (too soon for a line); the command ends there: 1/3 as counted.
    """
    now = [0.0]
    monkeypatch.setattr(_progress, "time", SimpleNamespace(monotonic=lambda: now[0]))
    console = _console(terminal=False)
    with StepBar("critic-study", 0, False, console=console) as bar:
        assert bar.bar is None  # no live bar in a log
        bar.phase("rollouts", 100)
        for _ in range(100):
            now[0] += 1
            bar.step()
        bar.phase("fits", 40)
        for _ in range(4):
            now[0] += 20
            bar.step()
        bar.phase("scoring", 3)
        now[0] += 5
        bar.step()
    assert console.file.getvalue().splitlines() == [
        "critic-study rollouts: 0/100 started",
        "critic-study rollouts: 30/100 (30%) 0:00:30 elapsed, ~0:01:10 left",
        "critic-study rollouts: 60/100 (60%) 0:01:00 elapsed, ~0:00:40 left",
        "critic-study rollouts: 90/100 (90%) 0:01:30 elapsed, ~0:00:10 left",
        "critic-study rollouts: 100/100 done in 0:01:40",
        "critic-study fits: 0/40 started",
        "critic-study fits: 2/40 (5%) 0:00:40 elapsed, ~0:12:40 left",
        "critic-study fits: 4/40 (10%) 0:01:20 elapsed, ~0:12:00 left",
        "critic-study fits: 40/40 done in 0:01:20",
        "critic-study scoring: 0/3 started",
        "critic-study scoring: 1/3 stopped after 0:00:05",
    ]


def test_a_log_line_names_the_current_rollout_and_an_error_ends_without_a_last_line(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(_progress, "time", SimpleNamespace(monotonic=lambda: now[0]))
    console = _console(terminal=False)
    with StepBar("eval", 4, False, console=console) as bar:
        bar.describe("go2 descriptor vx=1")
        for _ in range(4):
            now[0] += 0.5
            bar.step()
    try:
        with StepBar("diagnose", 4, False, console=console) as bar:
            bar.step()
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass
    assert console.file.getvalue().splitlines() == [
        "eval: 0/4 started",
        "eval go2 descriptor vx=1: 4/4 done in 0:00:02",
        "diagnose: 0/4 started",
    ]


def test_log_pace_of_train_is_each_percent_of_the_run_from_where_it_resumed():
    """`morfic train` in a log: a line each 1 % of max_iterations (1000 -> each 10), the last one always."""
    pace = LogPace(1000, 0.01, done=995)  # resumed at iteration 995
    assert [it for it in range(996, 1001) if pace.due(it)] == [1000]
    pace = LogPace(250, 0.01, done=0)  # 2 iterations a line
    assert [it for it in range(1, 9) if pace.due(it)] == [2, 4, 6, 8]
    pace = LogPace(40, 0.05, min_s=30.0)  # 2 units a line, 30 s apart: a mark passed too soon waits for the time
    assert [pace.due(2, 10.0), pace.due(3, 31.0), pace.due(4, 40.0), pace.due(6, 62.0)] == [False, True, False, True]


def test_clock_text_and_time_left():
    assert _progress.clock_text(125.4) == "0:02:05" and _progress.clock_text(3 * 3600 + 61) == "3:01:01"
    assert _progress.time_left(30.0, 3, 10) == "~0:01:10" and _progress.time_left(0.0, 0, 10) == "?"


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
    lines = err.splitlines()  # stderr is captured, not a terminal: StepBar's plain lines
    assert any(line.startswith("eval go2 descriptor vx=1: 4/4 done in ") for line in lines), err
    assert "eval videos: 0/2 started" in lines, err
    videos = [line for line in lines if line.startswith("eval videos go2-descriptor-vx1")]
    assert videos and ": 2/2 done in " in videos[-1], err
