"""Progress on stderr: a rich bar on a terminal, plain lines in a log (``nohup``, CI, a queue script).

:class:`StepBar` counts a command's policy steps (eval, diagnose) or the stages of its work (critic-study).
:class:`LogPace` decides when a log gets its next line, for StepBar and for ``morfic train``'s iteration lines.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress, TaskID

LOG_FRACTION = 0.05
"""A log gets a StepBar line each 5 % of a phase's work ..."""
LOG_MIN_S = 30.0
"""... and at most one every 30 s, so a two-hour ``critic-study`` log stays short."""


@dataclass
class LogPace:
    """When a log gets its next progress line: each ``fraction`` of ``total`` units of work, at most every ``min_s``.

    :meth:`due` is True (and remembers the line) once ``done`` has crossed a multiple of :attr:`every` since the last
    line and ``min_s`` seconds have passed since it; a multiple crossed too soon is printed as soon as the time has
    passed. The end of the work (``done >= total``) is always due.
    """

    total: int
    fraction: float
    min_s: float = 0.0
    done: int = 0
    """Units done at the last line (or at the start)."""
    at: float = 0.0
    """Time of the last line (or of the start), in the caller's clock."""

    @property
    def every(self) -> int:
        """Units between lines: ``max(1, int(total * fraction))``."""
        return max(1, int(self.total * self.fraction))

    def due(self, done: int, now: float = 0.0) -> bool:
        if done < self.total and (done // self.every <= self.done // self.every or now - self.at < self.min_s):
            return False
        self.done, self.at = done, now
        return True


def clock_text(seconds: float) -> str:
    """``H:MM:SS`` (as rich's bar shows time), e.g. ``0:02:05`` for 125.4 s."""
    s = round(max(seconds, 0.0))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def time_left(elapsed: float, done: int, total: int) -> str:
    """``~H:MM:SS`` left at the pace so far (``elapsed`` seconds for ``done`` of ``total`` units); ``?`` before any."""
    return f"~{clock_text(elapsed / done * (total - done))}" if done > 0 else "?"


class StepBar:
    """A progress bar over ``total`` policy steps, labelled ``label``; nothing is shown when ``quiet``.

    ``with StepBar("eval", total, quiet) as bar``: ``bar.describe(text)`` names the current rollout,
    ``bar.step()`` advances one policy step; ``bar.phase(text, total)`` starts the next stage of a command whose
    stages count different work (``critic-study``: rollout steps, gradient steps, sample sets).

    On a terminal it is a live rich bar. When stderr is not a terminal (a log file), it prints plain lines instead:
    one when a phase starts (``critic-study fits: 0/40 started``), one at most each 5 % of the phase's work and
    30 s (``critic-study fits: 12/40 (30%) 0:01:05 elapsed, ~0:02:32 left``), one when the phase ends
    (``critic-study fits: 40/40 done in 0:03:37``). ``console``: where to draw (default: stderr).
    """

    def __init__(self, label: str, total: int, quiet: bool, console: Console | None = None) -> None:
        self.label, self.total, self.quiet, self.console = label, total, quiet, console
        self.bar: Progress | None = None
        self.task: TaskID = cast("TaskID", 0)  # the current phase's task of ``bar``, set with it
        self.lines: _Lines | None = None

    def __enter__(self) -> StepBar:
        if self.quiet:
            return self
        from rich.console import Console

        console = self.console or Console(stderr=True, emoji=False)
        if not console.is_terminal:
            self.lines = _Lines(self.label, console)
            if self.total:  # a bar opened without work of its own (total 0) waits for its first phase
                self.lines.start("", self.total)
            return self
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        self.bar = Progress(
            TextColumn(f"[bold]{self.label}[/] {{task.description}}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            console=console,
        )
        self.bar.__enter__()
        self.task = self.bar.add_task("", total=self.total)
        return self

    def phase(self, text: str, total: int) -> None:
        """Start a new stage of the command with its own ``total`` (the previous one is shown complete)."""
        if self.lines is not None:
            self.lines.end(complete=True)
            self.lines.start(text, total)
        if self.bar is not None:
            current = next(t for t in self.bar.tasks if t.id == self.task)
            if current.total:
                self.bar.update(self.task, completed=current.total)
            else:  # the bar was opened without work of its own (total 0): the stages replace it
                self.bar.remove_task(self.task)
            self.task = self.bar.add_task(text, total=total)

    def describe(self, text: str) -> None:
        if self.lines is not None:
            self.lines.text = text
        if self.bar is not None:
            self.bar.update(self.task, description=text)

    def step(self, *_: object) -> None:
        if self.lines is not None:
            self.lines.step()
        if self.bar is not None:
            self.bar.advance(self.task)

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        if self.lines is not None and exc_type is None:  # an error or Ctrl-C says what happened itself
            self.lines.end(complete=False)
        if self.bar is not None:
            self.bar.__exit__(exc_type, *exc)


class _Lines:
    """StepBar's plain lines for a log: the current phase (text, done/total, start time) and its :class:`LogPace`."""

    def __init__(self, label: str, console: Console) -> None:
        self.label, self.console = label, console
        self.text, self.done, self.total, self.started = "", 0, 0, 0.0
        self.open = False
        self.pace = LogPace(0, LOG_FRACTION, LOG_MIN_S)

    def start(self, text: str, total: int) -> None:
        self.text, self.done, self.total, self.started = text, 0, total, time.monotonic()
        self.open = True
        self.pace = LogPace(total, LOG_FRACTION, LOG_MIN_S, at=self.started)
        self._write(f"0/{total} started")

    def step(self) -> None:
        if not self.open:
            return
        self.done += 1
        if self.done >= self.total:
            self.end(complete=True)
            return
        now = time.monotonic()
        if self.pace.due(self.done, now):
            elapsed = now - self.started
            self._write(
                f"{self.done}/{self.total} ({100 * self.done // self.total}%) {clock_text(elapsed)} elapsed, "
                f"{time_left(elapsed, self.done, self.total)} left"
            )

    def end(self, complete: bool) -> None:
        """The phase's last line; ``complete``: its work is over (the next phase starts), else as counted."""
        if not self.open:
            return
        self.open = False
        done = self.total if complete else self.done
        verb = "done in" if done >= self.total else "stopped after"
        self._write(f"{done}/{self.total} {verb} {clock_text(time.monotonic() - self.started)}")

    def _write(self, what: str) -> None:
        head = f"{self.label} {self.text}".rstrip()
        self.console.file.write(f"{head}: {what}\n")  # plain text: no markup, no wrapping at the console's width
        self.console.file.flush()
