"""bf16 matrix products on a CPU without bf16 kernels: computed in float32 from the bf16 operands.

The ``cpu`` preset trains under bf16 autocast (``ppo.use_mixed_precision``, docs/training.md). oneDNN runs bf16
matrix products natively on x86 CPUs with AVX512-BF16 or AMX (and emulates them with plain AVX-512; not measured
here): it multiplies the bf16 operands, sums the products in float32 and rounds the result to bf16. On a CPU with
AVX2 only, torch has no such kernels and falls back to reference loops: measured on an AVX2-only 2-core AMD EPYC
(docs/benchmarks-history.md, "bf16 autocast on a CPU without bf16 kernels"), the cpu preset's concat iteration
took 57.9 s under bf16 autocast and 7.8 s in float32.

There, :class:`Bf16MatmulInFloat32` computes each bf16 matrix product (``linear``, ``matmul``, ``mm``, ``addmm``,
``bmm``, ``baddbmm``; forward and backward) as the float32 product of the same bf16 operands, rounded to bf16. A
product of two bf16 numbers is exact in float32 (8 + 8 significant bits), so this is the native kernel's
computation; only the order of the float32 sums may differ. Measured against the native (slow) kernels on the AVX2
machine, a bf16-autocast forward and backward pass of a 768-512-256-128 MLP on 3,072 rows gave 90-99.6 % of the
output and gradient entries bit-identical and relative differences of 3e-5 to 9e-4, against 2.4e-3 to 4.4e-3
between bf16 and float32 (docs/benchmarks-history.md). Every other op of the autocast region runs as before (elementwise
ops on bf16 tensors are fast on any CPU). The cpu preset then takes 9.0 s per iteration there, 1.2x its float32
time, instead of 57.9 s.

``einsum`` needs one more step: autocast casts no CPU ``einsum``, only the ``bmm`` inside, and under
``torch.inference_mode`` (the rollout) the whole ``einsum`` reaches the mode, past autocast. One of float32 operands
only (bot's per-node embeddings) then ran in float32 and returned float32, not the native bf16 product; entering the
mode also enters :class:`_EinsumAsAutocast`, which rounds such operands to bf16 while autocast is on. bot's rollout
forward now differs from the native one by 1e-4 (relative; 60-93 % of the entries bit-identical), against 2.5e-3
between native and float32 (it was 2.5e-3 from both). Profiled on the AVX2 machine, bot (8 transformer layers)
reaches the mode with no fused op (bot.py writes its layers out): every bf16 product is one of the above, 70 % of
its update's time, and an update on a cpu-preset mini-batch takes 1.1-1.3x its float32 time (5.2-5.4 against
4.0-4.8 s, interleaved; native kernels: 124 s).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch
from torch.overrides import TorchFunctionMode
from torch.utils import _pytree as pytree
from torch.utils._python_dispatch import TorchDispatchMode

#: ``bf16_matmul`` of a run: the native bf16 kernels, or float32 products of the bf16 operands (this module).
NATIVE, FLOAT32 = "native", "float32"

_aten = torch.ops.aten
_MATMULS = frozenset(
    {
        _aten.mm.default,
        _aten.addmm.default,
        _aten.bmm.default,
        _aten.baddbmm.default,
        _aten.linear.default,
        _aten.matmul.default,
        _aten.einsum.default,
    }
)
"""The products autocast runs in bf16 on the CPU, as they reach a dispatch mode: ``linear``, ``matmul`` and
``einsum`` whole under ``torch.inference_mode`` (the rollout), decomposed into ``mm`` / ``addmm`` / ``bmm`` /
``baddbmm`` where autograd records them (the update, forward and backward). A whole ``einsum`` arrives before
autocast would cast its operands (it casts the ``bmm`` inside): :class:`_EinsumAsAutocast` rounds its float32
operands to bf16 first (urma's attention pool mixes float32 weights and bf16 values; bot's embeddings are float32)."""

_EINSUMS = frozenset({torch.functional.einsum, torch._C._VariableFunctions.einsum})  # type: ignore[attr-defined]
"""``torch.einsum`` as a function mode sees it (the Python wrapper, or the binding called directly)."""


def cpu_bf16_kernels() -> bool | None:
    """Whether oneDNN has fast bf16 matrix kernels on this CPU.

    Returns:
        True (AVX512-BF16, AMX or AVX-512), False (none: AVX2 only), None where torch cannot tell (a build without
        oneDNN's probe).
    """
    probe = getattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported", None)
    if probe is None:
        return None
    try:
        return bool(probe())
    except RuntimeError:  # a build without oneDNN
        return None


def bf16_matmul(device: str, kernels: bool | None) -> str:
    """How bf16 autocast's matrix products run: :data:`FLOAT32` on a CPU without bf16 kernels, else :data:`NATIVE`.

    Args:
        device: The training device ("cpu", "cuda", "cuda:0", ...); a GPU has its own bf16 units.
        kernels: :func:`cpu_bf16_kernels` of this machine (None, unknown: native).
    """
    return FLOAT32 if not device.startswith("cuda") and kernels is False else NATIVE


class Bf16MatmulInFloat32(TorchDispatchMode):
    """While active, a matrix product with bf16 operands is the float32 product of those operands, rounded to bf16.

    Sits below autograd and autocast in the dispatcher, so it sees the products autocast casts to bf16 and those of
    their backward pass. Products of float32 tensors pass through unchanged. Entering it also enters
    :class:`_EinsumAsAutocast`, which gives a whole ``einsum`` the bf16 operands autocast would give its ``bmm``.
    """

    def __enter__(self):  # noqa: ANN204, D105
        einsums = _EinsumAsAutocast()
        einsums.__enter__()
        self.__dict__.setdefault("_einsums", []).append(einsums)  # a stack: the mode may be re-entered
        return super().__enter__()

    def __exit__(self, exc_type, exc_val, exc_tb):  # noqa: ANN001, ANN204, D105
        try:
            super().__exit__(exc_type, exc_val, exc_tb)
        finally:
            self._einsums.pop().__exit__(exc_type, exc_val, exc_tb)

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):  # noqa: ANN001, D105
        kwargs = kwargs or {}
        if func in _MATMULS and any(t.dtype == torch.bfloat16 for t in _tensors(args)):
            return func(*pytree.tree_map(_bf16_as_float32, args), **kwargs).to(torch.bfloat16)
        return func(*args, **kwargs)


class _EinsumAsAutocast(TorchFunctionMode):
    """Inside a bf16 CPU autocast region, ``torch.einsum`` of float32 operands gets them rounded to bf16 first.

    On the CPU, autocast casts no ``einsum``, only the ``bmm`` it decomposes into. Under ``torch.inference_mode`` (the
    rollout) the whole ``einsum`` reaches :class:`Bf16MatmulInFloat32` instead, where autocast no longer acts: without
    this cast an einsum of float32 operands (bot's per-node embeddings) ran in float32 and returned float32 where the
    native kernels give the bf16 product. A dispatch mode cannot see whether autocast is on; a function mode, above
    the dispatcher, can. Outside autocast (``float32_linear``'s heads) the einsum is left alone.
    """

    def __torch_function__(self, func, types, args=(), kwargs=None):  # noqa: ANN001, D105
        kwargs = kwargs or {}
        if func in _EINSUMS and torch.is_autocast_enabled("cpu") and torch.get_autocast_dtype("cpu") == torch.bfloat16:
            args = pytree.tree_map(_float32_as_bf16, args)
        return func(*args, **kwargs)


def _float32_as_bf16(a: object) -> object:
    """A float32 tensor rounded to bf16, as autocast casts a product's operand; anything else as it is."""
    return a.to(torch.bfloat16) if isinstance(a, torch.Tensor) and a.dtype == torch.float32 else a


def _tensors(args: tuple) -> list[torch.Tensor]:
    """The tensors among a dispatched op's arguments, in lists too (``einsum``'s operands)."""
    return [a for a in pytree.tree_leaves(args) if isinstance(a, torch.Tensor)]


def _bf16_as_float32(a: object) -> object:
    """A bf16 tensor widened to float32 (exactly); anything else as it is.

    A whole ``einsum``'s float32 operands were rounded to bf16 before it reached the mode (:class:`_EinsumAsAutocast`).
    """
    return a.float() if isinstance(a, torch.Tensor) and a.dtype == torch.bfloat16 else a


@contextlib.contextmanager
def matmul_region(mode: str | None) -> Iterator[None]:
    """:class:`Bf16MatmulInFloat32` while inside when ``mode`` is :data:`FLOAT32`; else nothing."""
    if mode != FLOAT32:
        yield
        return
    with Bf16MatmulInFloat32():
        yield


def float32_note(mode: str | None) -> str | None:
    """The note a run prints when its bf16 matrix products run in float32 (``mode`` :data:`FLOAT32`); else None."""
    if mode != FLOAT32:
        return None
    return (
        "note: this CPU has no bf16 matrix kernels (AVX2 only), so the run's bf16 matrix products are computed in "
        "float32 from the same bf16 operands and rounded to bf16: the native kernels' values up to the order of "
        "float32 sums, at 1.2-1.5x float32's time (film's cpu preset 1.2x, bot's rollout 1.5x) instead of 7.5x "
        "(morfic_cli/rl/precision.py)."
    )
