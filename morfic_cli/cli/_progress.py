"""A rich progress bar over the policy steps of a command's rollouts (eval, diagnose), on stderr."""

from __future__ import annotations


class StepBar:
    """A progress bar over ``total`` policy steps, labelled ``label``; nothing is shown when ``quiet``.

    ``with StepBar("eval", total, quiet) as bar``: ``bar.describe(text)`` names the current rollout,
    ``bar.step()`` advances one policy step; ``bar.phase(text, total)`` starts the next stage of a command whose
    stages count different work (``critic-study``: rollout steps, gradient steps, sample sets).
    """

    def __init__(self, label: str, total: int, quiet: bool) -> None:
        self.label, self.total, self.quiet = label, total, quiet
        self.bar = None
        self.task = None

    def __enter__(self) -> StepBar:
        if not self.quiet:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.bar = Progress(
                TextColumn(f"[bold]{self.label}[/] {{task.description}}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                console=Console(stderr=True, emoji=False),
            )
            self.bar.__enter__()
            self.task = self.bar.add_task("", total=self.total)
        return self

    def phase(self, text: str, total: int) -> None:
        """Start a new stage of the command with its own ``total`` (the previous one is shown complete)."""
        if self.bar is not None:
            current = next(t for t in self.bar.tasks if t.id == self.task)
            if current.total:
                self.bar.update(self.task, completed=current.total)
            else:  # the bar was opened without work of its own (total 0): the stages replace it
                self.bar.remove_task(self.task)
            self.task = self.bar.add_task(text, total=total)

    def describe(self, text: str) -> None:
        if self.bar is not None:
            self.bar.update(self.task, description=text)

    def step(self, *_: object) -> None:
        if self.bar is not None:
            self.bar.advance(self.task)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)
