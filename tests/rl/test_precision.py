"""bf16 autocast on a CPU without bf16 kernels: the probe, the warning's cases, and `morfic train` printing it."""

from __future__ import annotations

import json

import pytest
import torch

from morfic_cli.rl import precision
from morfic_cli.rl.precision import cpu_bf16_kernels, slow_bf16_warning


@pytest.mark.parametrize(("mixed", "device", "kernels", "warns"), [
    (True, "cpu", False, True),     # the case: bf16 autocast, CPU without kernels
    (True, "cpu", True, False),     # AVX512-BF16 / AMX: the fast path
    (True, "cpu", None, False),     # unknown: say nothing rather than something false
    (False, "cpu", False, False),   # float32 run: nothing to warn about
    (True, "cuda", False, False),   # a GPU has its own bf16 units
    (True, "cuda:1", False, False),
])
def test_slow_bf16_warning_only_for_bf16_autocast_on_a_cpu_without_kernels(mixed, device, kernels, warns):
    message = slow_bf16_warning(mixed, device, kernels)
    assert (message is not None) is warns
    if warns:
        assert message.startswith("Warning: ")
        assert "--set ppo.use_mixed_precision=false" in message
        assert "57.9 s/iteration in bf16, 7.8 s in float32" in message  # MEASURED_AVX2_S_PER_ITERATION


def test_cpu_bf16_kernels_is_onednns_answer(monkeypatch):
    assert cpu_bf16_kernels() is bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())

    class NoProbe:  # a torch build without the probe: unknown, not False
        pass

    monkeypatch.setattr(torch.ops, "mkldnn", NoProbe())
    assert cpu_bf16_kernels() is None


@pytest.mark.parametrize(("kernels", "mixed", "warns"), [(False, "true", True), (True, "true", False),
                                                         (False, "false", False)])
def test_train_prints_the_warning_also_when_quiet(run_cli, monkeypatch, kernels, mixed, warns):
    monkeypatch.setattr(precision, "cpu_bf16_kernels", lambda: kernels)
    code, out, err = run_cli("train", "--preset", "smoke", "--set", "max_iterations=1", "--set",
                             f"ppo.use_mixed_precision={mixed}", "--name", f"bf16-{kernels}-{mixed}",
                             "--format", "json", "-q")
    assert code == 0, err
    assert json.loads(out)["iteration"] == 1  # a warning, not an error: the run trains
    assert ("Warning: this CPU has no bf16 matrix kernels" in " ".join(err.split())) is warns


def test_reproduce_warns_only_while_a_bf16_run_is_left_to_train(tmp_path, run_cli):
    import dataclasses

    from morfic_cli.pipeline import Pipeline, reproduce_cfg
    from morfic_cli.store import Store

    store = Store(tmp_path / "store")
    bf16 = ("ppo.use_mixed_precision=true",)
    assert Pipeline(store, reproduce_cfg("cpu", variants=("film", "ppo"))).trains_in_bf16()  # the cpu preset's bf16
    assert not Pipeline(store, reproduce_cfg("smoke", variants=("film",))).trains_in_bf16()  # smoke: float32
    assert not Pipeline(store, dataclasses.replace(reproduce_cfg("cpu", variants=("film",)),
                                                   train_overrides=("ppo.use_mixed_precision=false",))).trains_in_bf16()
    smoke_bf16 = dataclasses.replace(reproduce_cfg("smoke", variants=("film",)), train_overrides=bf16)
    assert Pipeline(store, smoke_bf16).trains_in_bf16()
    code, _, err = run_cli("train", "--preset", "smoke", "--set", bf16[0], "--name", "film-smoke-s0",
                           "--store", str(store.root), "-q")
    assert code == 0, err
    assert not Pipeline(store, smoke_bf16).trains_in_bf16()  # film-smoke-s0 is finished: nothing left to train
    assert not Pipeline(store, dataclasses.replace(reproduce_cfg("cpu", variants=("film",)),
                                                   bundles=tmp_path)).trains_in_bf16()  # shipped: imports, no training
