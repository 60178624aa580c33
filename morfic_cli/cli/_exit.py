"""The interpreter's exit after a command: quick, so the clocks we publish miss little of it."""

from __future__ import annotations

import atexit
import gc


def freeze_at_exit() -> None:
    """Skip the garbage collection of the interpreter's exit: ``gc.freeze()`` registered with ``atexit``.

    At exit Python collects garbage over every object torch, scipy and matplotlib made, several passes while it
    tears the modules down: 1.5-3 s after the result is printed on a busy 2-core machine, after the training clock
    stopped. Frozen objects are left to the OS, which frees the process's memory anyway. Only at exit: a process
    that goes on (tests calling a command) collects garbage as usual. ``main`` calls it for every command.
    """
    atexit.unregister(gc.freeze)  # once, however often the command runs in one process
    atexit.register(gc.freeze)
