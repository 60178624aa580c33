"""`morfic train`'s clock: it starts at the process's start and the exit after it skips the garbage collection."""

import subprocess
import sys
import time
from pathlib import Path

import pytest

from morfic_cli.cli.train import process_start

IMPORTED = time.perf_counter()  # this module's import: after the process started, before the test runs


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the start time from Linux's /proc")
def test_the_clock_starts_at_the_process_start_not_at_the_command():
    assert process_start() < IMPORTED


# A cycle of garbage with a finaliser, left to the interpreter's exit (automatic collection off until then).
EXIT = """
import gc
import sys
gc.disable()


class Loud:
    def __del__(self):
        sys.stdout.write("collected at exit\\n")


loud = Loud()
loud.me = loud
del loud
if sys.argv[1] == "freeze":
    from morfic_cli.cli._exit import freeze_at_exit

    freeze_at_exit()
    freeze_at_exit()  # once is enough; twice changes nothing
"""


def test_the_exit_after_training_skips_the_garbage_collection():
    """Python collects the cycle as it exits; after freeze_at_exit (as `morfic`'s main calls it) it leaves it."""
    out = {
        how: subprocess.run(
            [sys.executable, "-c", EXIT, how], capture_output=True, text=True, timeout=300, check=True
        ).stdout
        for how in ("plain", "freeze")
    }
    assert out == {"plain": "collected at exit\n", "freeze": ""}


def test_a_log_gets_a_line_an_iteration_with_the_time_left_but_the_last(run_cli, tmp_path):
    """stderr is captured (not a terminal): 2 iterations -> a line each (1 % of 2 rounds up to 1 iteration)."""
    code, _, err = run_cli("train", "--preset", "smoke", "--logger", "none", "--store", str(tmp_path / "store"))
    assert code == 0, err
    lines = [line for line in err.splitlines() if line.startswith("it ")]
    assert [line.split()[1] for line in lines] == ["1/2", "2/2"], err
    assert lines[0].endswith(" left") and lines[0].split()[-2].startswith("~0:"), err
    assert not lines[1].endswith(" left"), err
