"""The OpenMP wait policy of a morfic process (morfic_cli/threads.py)."""

from __future__ import annotations

import subprocess
import sys

from morfic_cli.threads import configure_openmp, user_environment


def test_passive_unless_the_user_chose_a_policy():
    env: dict[str, str] = {"HOME": "/h"}
    assert configure_openmp(env) == "PASSIVE"
    assert env["OMP_WAIT_POLICY"] == "PASSIVE"
    assert user_environment(env) == {"HOME": "/h"}  # a child running other code gets the user's environment
    mine = {"OMP_WAIT_POLICY": "ACTIVE"}
    assert configure_openmp(mine) == "ACTIVE"
    assert mine == {"OMP_WAIT_POLICY": "ACTIVE"}
    assert user_environment(mine) == {"OMP_WAIT_POLICY": "ACTIVE"}


def test_the_entry_point_sets_it_before_torch_is_imported():
    code = (
        "import os, sys; os.environ.pop('OMP_WAIT_POLICY', None); from morfic_cli.cli import main\n"
        "try:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
        "print(os.environ.get('OMP_WAIT_POLICY'), 'torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split()[-2:] == ["PASSIVE", "False"]
