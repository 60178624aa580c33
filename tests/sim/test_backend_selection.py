"""Choosing a simulation backend and device: names, aliases and the errors a user can cause (no GPU needed)."""

from __future__ import annotations

import sys

import pytest
import torch

from morfic_cli.config import SimCfg
from morfic_cli.errors import MorficError
from morfic_cli.morphology.robots import load_robot
from morfic_cli.sim.factory import make_backend


def test_unknown_backend_lists_the_valid_ones():
    with pytest.raises(MorficError, match="valid backends are: cpu, warp"):
        make_backend(SimCfg(backend="isaac"), load_robot("go2"), 1, template=True)


def test_warp_without_mujoco_warp_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco_warp", None)  # import mujoco_warp -> ImportError
    with pytest.raises(MorficError, match=r"pip install 'morfic\[gpu\]'"):
        make_backend(SimCfg(backend="warp"), load_robot("go2"), 1, template=True)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the message on a machine without CUDA")
def test_warp_on_cuda_without_cuda_is_a_clear_error():
    with pytest.raises(MorficError, match="no CUDA device") as exc:
        make_backend(SimCfg(backend="warp", device="cuda"), load_robot("go2"), 1, template=True)
    assert "--device cpu" in str(exc.value)
