"""A rich progress bar over the policy steps of a command's rollouts (eval, diagnose), on stderr."""

from __future__ import annotations


class StepBar:
    """A progress bar over ``total`` policy steps, labelled ``label``; nothing is shown when ``quiet``.

    ``with StepBar("eval", total, quiet) as bar``: ``bar.describe(text)`` names the current rollout,
    ``bar.step()`` advances one policy step.
    """

    def __init__(self, label: str, total: int, quiet: bool) -> None:
        self.label, self.total, self.quiet = label, total, quiet
        self.bar = None
        self.task = None

    def __enter__(self) -> StepBar:
        if not self.quiet:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.bar = Progress(TextColumn(f"[bold]{self.label}[/] {{task.description}}"), BarColumn(),
                                MofNCompleteColumn(), TimeRemainingColumn(), console=Console(stderr=True))
            self.bar.__enter__()
            self.task = self.bar.add_task("", total=self.total)
        return self

    def describe(self, text: str) -> None:
        if self.bar is not None:
            self.bar.update(self.task, description=text)

    def step(self, *_: object) -> None:
        if self.bar is not None:
            self.bar.advance(self.task)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
