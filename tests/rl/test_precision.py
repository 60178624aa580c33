"""bf16 matrix products on a CPU without bf16 kernels: float32 products of the bf16 operands (rl/precision.py)."""

from __future__ import annotations

import dataclasses
import json
import os

import pytest
import torch

from morfic_cli.rl import ppo as ppo_module
from morfic_cli.rl.precision import (
    FLOAT32,
    NATIVE,
    Bf16MatmulInFloat32,
    bf16_matmul,
    cpu_bf16_kernels,
    float32_note,
    matmul_region,
)
from morfic_cli.store import Store

BF16 = torch.bfloat16


@pytest.mark.parametrize(
    ("device", "kernels", "mode"),
    [
        ("cpu", False, FLOAT32),  # AVX2 only: emulate
        ("cpu", True, NATIVE),  # AVX512-BF16 / AMX
        ("cpu", None, NATIVE),  # unknown: leave torch alone
        ("cuda", False, NATIVE),  # a GPU has its own bf16 units
        ("cuda:1", False, NATIVE),
    ],
)
def test_bf16_matmul_is_float32_only_on_a_cpu_without_kernels(device, kernels, mode):
    assert bf16_matmul(device, kernels) == mode
    assert (float32_note(mode) is not None) is (mode == FLOAT32)


def test_cpu_bf16_kernels_is_onednns_answer(monkeypatch):
    assert cpu_bf16_kernels() is bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())

    class NoProbe:  # a torch build without the probe: unknown, not False
        pass

    monkeypatch.setattr(torch.ops, "mkldnn", NoProbe())
    assert cpu_bf16_kernels() is None


def test_products_of_exact_sums_equal_the_native_kernels_and_the_hand_values():
    a = torch.tensor([[1.0, 2.0], [3.0, 4.0]], dtype=BF16)
    b = torch.tensor([[5.0, 6.0], [7.0, 8.0]], dtype=BF16)
    c = torch.tensor([[1.0, 1.0]], dtype=BF16)
    d = torch.tensor([[256.0], [1.0]], dtype=BF16)
    native = (a @ b, c @ d, torch.addmm(torch.ones(2, 2, dtype=BF16), a, b), torch.bmm(a[None], b[None]))
    with Bf16MatmulInFloat32():
        emulated = (a @ b, c @ d, torch.addmm(torch.ones(2, 2, dtype=BF16), a, b), torch.bmm(a[None], b[None]))
    assert emulated[0].dtype == BF16 and emulated[0].tolist() == [[19.0, 22.0], [43.0, 50.0]]
    assert emulated[1].item() == 256.0  # 257 is a tie between bf16's 256 and 258: round to even
    assert emulated[2].tolist() == [[20.0, 23.0], [44.0, 51.0]]
    for e, n in zip(emulated, native, strict=True):
        assert torch.equal(e, n)


def test_float32_products_pass_through_bit_identical():
    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(33, 17, generator=g), torch.randn(17, 9, generator=g)
    with Bf16MatmulInFloat32():
        inside = a @ b
    assert inside.dtype == torch.float32 and torch.equal(inside, a @ b)


def _autocast_pass(model: torch.nn.Module, x: torch.Tensor, mode: str | None, mixed: bool = True):
    """Output and gradients of one bf16-autocast forward/backward pass (float32 when not ``mixed``)."""
    model.zero_grad()
    with matmul_region(mode), torch.autocast("cpu", dtype=BF16, enabled=mixed):
        y = model(x).float()
    with matmul_region(mode):
        (y**2).mean().backward()
    return [y.detach(), *(p.grad.clone() for p in model.parameters())]


def _rel(a: list[torch.Tensor], b: list[torch.Tensor]) -> list[float]:
    return [float((x - y).norm() / y.norm()) for x, y in zip(a, b, strict=True)]


def test_an_autocast_mlp_pass_is_the_native_one_up_to_the_order_of_sums():
    torch.manual_seed(0)
    model = torch.nn.Sequential(
        torch.nn.Linear(48, 64), torch.nn.ELU(), torch.nn.Linear(64, 32), torch.nn.ELU(), torch.nn.Linear(32, 8)
    )
    x = torch.randn(96, 48)
    native = _autocast_pass(model, x, NATIVE)
    emulated = _autocast_pass(model, x, FLOAT32)
    full = _autocast_pass(model, x, None, mixed=False)
    assert emulated[0].dtype == torch.float32 and len(emulated) == 1 + 6
    # bf16 rounding (emulated and native alike) moves everything by ~1e-3 from float32; the two bf16 passes differ
    # only where a float32 sum in another order rounds to the neighbouring bf16 value
    for e_n, n_f in zip(_rel(emulated, native), _rel(native, full), strict=True):
        assert e_n < 0.25 * n_f
    with torch.inference_mode(), torch.autocast("cpu", dtype=BF16):  # the rollout: linear reaches the mode whole
        rollout_native = model(x)
        with Bf16MatmulInFloat32():
            rollout_emulated = model(x)
    assert rollout_emulated.dtype == BF16
    assert _rel([rollout_emulated.float()], [rollout_native.float()])[0] < 0.25 * _rel([native[0]], [full[0]])[0]


def test_a_whole_einsum_with_mixed_operands_is_autocasts_bf16_product():
    # under inference_mode einsum reaches the mode whole, before autocast casts its operands (urma's attention pool:
    # float32 softmax weights, bf16 values); autocast would round both to bf16 and multiply
    w = torch.tensor([[[0.5, 1.0 / 3.0], [0.5, 2.0 / 3.0]]])  # (n=1, t=2, s=2), float32; 1/3 is not a bf16 number
    v = torch.tensor([[[2.0], [4.0]]], dtype=BF16)  # (n=1, t=2, v=1)
    third, two_thirds = float(torch.tensor(1.0 / 3.0).to(BF16)), float(torch.tensor(2.0 / 3.0).to(BF16))
    hand = [[[0.5 * 2 + 0.5 * 4], [third * 2 + two_thirds * 4]]]
    with torch.inference_mode(), torch.autocast("cpu", dtype=BF16):
        native = torch.einsum("nts,ntv->nsv", w, v)
        with Bf16MatmulInFloat32():
            emulated = torch.einsum("nts,ntv->nsv", w, v)
    assert emulated.dtype == native.dtype == BF16
    assert torch.equal(emulated, native)
    assert emulated.tolist() == torch.tensor(hand).to(BF16).tolist()


def test_a_whole_einsum_of_float32_operands_is_autocasts_bf16_product():
    # autocast casts no CPU einsum, only the bmm inside; under inference_mode the whole einsum reached the mode with
    # float32 operands and ran in float32 (bot's per-node embeddings). 1 + 3/512 is not a bf16 number: autocast
    # rounds it to 1 + 4/512, so the native product is 1/128 where float32 gives 3/512.
    a, b = torch.tensor([[1.0 + 3 / 512, -1.0]]), torch.tensor([[1.0], [1.0]])
    with torch.inference_mode(), torch.autocast("cpu", dtype=BF16):
        native = torch.einsum("ij,jk->ik", a, b)
        with Bf16MatmulInFloat32():
            emulated = torch.einsum("ij,jk->ik", a, b)
            with torch.autocast("cpu", enabled=False):  # float32_linear's heads: left in float32
                outside = torch.einsum("ij,jk->ik", a, b)
    assert emulated.dtype == native.dtype == BF16
    assert emulated.item() == native.item() == 1 / 128
    assert outside.dtype == torch.float32 and outside.item() == 3 / 512
    a.requires_grad_(True)  # the update: autocast casts the bmm, the mode computes it
    with torch.autocast("cpu", dtype=BF16), Bf16MatmulInFloat32():
        updated = torch.einsum("ij,jk->ik", a, b)
    updated.float().sum().backward()
    assert updated.dtype == BF16 and updated.item() == 1 / 128 and a.grad.tolist() == [[1.0, 1.0]]


def test_bots_rollout_under_the_mode_is_the_native_one_up_to_the_order_of_sums():
    from tensordict import TensorDict

    from morfic_cli.rl.bot import BotActor, BotCritic

    torch.manual_seed(0)
    n, sizes = 16, {"d_model": 64, "nhead": 2, "num_layers": 8, "dim_feedforward": 128}  # BoT-Hard, the variant's
    obs = TensorDict(
        {"history": torch.randn(n, 48), "critic": torch.randn(n, 48), "privileged": torch.randn(n, 18)}, batch_size=[n]
    )
    actor = BotActor(obs, {"actor": ["history"]}, "actor", 12, **sizes)
    critic = BotCritic(obs, {"critic": ["critic", "privileged"]}, "critic", 1, **sizes)
    for model in (actor, critic):
        with torch.inference_mode():
            full = model.compute(obs)
            with torch.autocast("cpu", dtype=BF16):
                native = model.compute(obs)
                with Bf16MatmulInFloat32():
                    emulated = model.compute(obs)
        assert emulated.dtype == native.dtype == torch.float32  # float32 heads
        # before einsum was cast, the joint tokens stayed float32: as far from native as native from float32
        assert _rel([emulated], [native])[0] < 0.25 * _rel([native], [full])[0]
        assert float((emulated - native).abs().max()) <= 2**-7 * float(native.abs().max())


def test_urmas_attention_pool_runs_in_the_rollout_on_a_cpu_without_kernels():
    from morfic_cli.rl.urma import AttentionPool

    torch.manual_seed(0)
    pool = AttentionPool(description_dim=6, state_dim=3, slots=4)
    description, state = torch.randn(5, 12, 6), torch.randn(5, 12, 3)
    with torch.inference_mode(), torch.autocast("cpu", dtype=BF16):
        native, _ = pool(description, state)
        with Bf16MatmulInFloat32():
            emulated, _ = pool(description, state)
    assert emulated.shape == native.shape == (5, 4 * 4) and emulated.dtype == native.dtype
    assert float((emulated.float() - native.float()).abs().max()) <= 2**-7 * float(native.float().abs().max())


@pytest.mark.parametrize(
    ("kernels", "mixed", "mode"), [(False, "true", FLOAT32), (True, "true", NATIVE), (False, "false", None)]
)
def test_train_records_how_its_bf16_products_ran(run_cli, monkeypatch, kernels, mixed, mode):
    monkeypatch.setattr(ppo_module, "cpu_bf16_kernels", lambda: kernels)
    code, out, err = run_cli(
        "train",
        "--preset",
        "smoke",
        "--set",
        "max_iterations=1",
        "--set",
        f"ppo.use_mixed_precision={mixed}",
        "--name",
        f"bf16-{kernels}-{mixed}",
        "--format",
        "json",
    )
    assert code == 0, err
    meta = Store(os.environ["MORFIC_STORE"]).read_manifest(json.loads(out)["id"]).meta
    assert meta.get("bf16_matmul") == mode
    assert ("no bf16 matrix kernels" in " ".join(err.split())) is (mode == FLOAT32)


def test_reproduce_notes_it_only_while_a_bf16_run_is_left_to_train(tmp_path, run_cli):
    from morfic_cli.pipeline import Pipeline, reproduce_cfg

    store = Store(tmp_path / "store")
    bf16 = ("ppo.use_mixed_precision=true",)
    assert Pipeline(store, reproduce_cfg("cpu", variants=("film", "ppo"))).trains_in_bf16()  # the cpu preset's bf16
    assert not Pipeline(store, reproduce_cfg("smoke", variants=("film",))).trains_in_bf16()  # smoke: float32
    assert not Pipeline(
        store,
        dataclasses.replace(
            reproduce_cfg("cpu", variants=("film",)), train_overrides=("ppo.use_mixed_precision=false",)
        ),
    ).trains_in_bf16()
    smoke_bf16 = dataclasses.replace(reproduce_cfg("smoke", variants=("film",)), train_overrides=bf16)
    assert Pipeline(store, smoke_bf16).trains_in_bf16()
    code, _, err = run_cli(
        "train", "--preset", "smoke", "--set", bf16[0], "--name", "film-smoke-s0", "--store", str(store.root), "-q"
    )
    assert code == 0, err
    assert not Pipeline(store, smoke_bf16).trains_in_bf16()  # film-smoke-s0 is finished: nothing left to train
    assert not Pipeline(
        store, dataclasses.replace(reproduce_cfg("cpu", variants=("film",)), bundles=tmp_path)
    ).trains_in_bf16()  # shipped: imports, no training
