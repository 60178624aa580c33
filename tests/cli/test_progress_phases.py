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
