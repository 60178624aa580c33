"""Whether this CPU has fast bf16 matrix kernels, and the warning for bf16 autocast on a CPU that has none.

The ``cpu`` preset trains under bf16 autocast (``ppo.use_mixed_precision``, docs/training.md). oneDNN runs bf16
matrix products natively on x86 CPUs with AVX512-BF16 or AMX, and emulates them with plain AVX-512 (not measured
here); on a CPU with AVX2 only (no AVX-512) torch falls back to slow reference kernels. Measured on an AVX2-only
2-core AMD EPYC (docs/benchmarks.md, "bf16 autocast on a CPU without bf16 kernels"): the cpu preset's concat
iteration took 57.9 s under bf16 autocast and 7.8 s in float32, while on the AVX512-BF16 EPYC the experiment's runs
took 3.0-3.5 s.
"""

from __future__ import annotations

#: s/iteration of the cpu preset (concat, 512 envs) on the AVX2-only 2-core EPYC: bf16 autocast, float32.
MEASURED_AVX2_S_PER_ITERATION: tuple[float, float] = (57.9, 7.8)


def cpu_bf16_kernels() -> bool | None:
    """Whether oneDNN has fast bf16 matrix kernels on this CPU.

    Returns:
        True (AVX512-BF16, AMX or AVX-512), False (none: AVX2 only), None where torch cannot tell (a build without
        oneDNN's probe).
    """
    import torch

    probe = getattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported", None)
    if probe is None:
        return None
    try:
        return bool(probe())
    except RuntimeError:  # a build without oneDNN
        return None


def slow_bf16_warning(use_mixed_precision: bool, device: str, kernels: bool | None) -> str | None:
    """The warning for a run that would autocast to bf16 on a CPU without bf16 kernels; None when there is none.

    Args:
        use_mixed_precision: The run's ``ppo.use_mixed_precision``.
        device: The training device ("cpu", "cuda", "cuda:0", ...); a GPU has its own bf16 units.
        kernels: :func:`cpu_bf16_kernels` of this machine (None: unknown, no warning).
    """
    if not use_mixed_precision or device.startswith("cuda") or kernels is not False:
        return None
    slow, fast = MEASURED_AVX2_S_PER_ITERATION
    return (
        "Warning: this CPU has no bf16 matrix kernels (oneDNN reports no AVX512-BF16, AMX or AVX-512), and this run "
        f"autocasts to bf16 (ppo.use_mixed_precision=true, the cpu preset's setting): expect it to run several times "
        f"slower than in float32 (cpu preset on an AVX2-only EPYC: {slow:g} s/iteration in bf16, {fast:g} s in "
        "float32). --set ppo.use_mixed_precision=false trains in float32 instead; that run is then not numerically "
        "the same as runs trained in bf16 (the shipped ones)."
    )
