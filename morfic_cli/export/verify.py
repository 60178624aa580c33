"""Checks of an export: the runtime reproduces the torch actor, and the metadata matches the robot models.

:func:`verify_outputs` feeds random observation histories (and descriptors) to the exported model through its
runtime (onnxruntime or TorchScript) and to the trained :class:`~morfic_cli.rl.models.MorficActor` itself, at the
full batch and at batch 1 (the dynamic batch axis), and reports the largest absolute difference.
:func:`model_mismatches` compares the metadata's joint order, gains and limits with the generated MuJoCo model.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import mujoco
import numpy as np
import torch
from tensordict import TensorDict

from morfic_cli.export.runtime import Runner

TOLERANCE = 1e-5
"""Largest accepted |runtime - torch| on any action or joint target (issue: < 1e-5)."""


@dataclass(frozen=True)
class Verification:
    """Result of :func:`verify_outputs`.

    Attributes:
        runtime: What ran the exported model, e.g. ``onnxruntime 1.18.0``.
        samples: Random inputs compared.
        batch_sizes: Batch sizes the model was run at.
        max_abs_diff: max |a_runtime - a_torch| over samples and joints.
        max_abs_diff_targets: The same for ``joint_targets`` (None when the model has no such output).
        tolerance: The bound both must stay under.
        ok: Both differences are finite and below ``tolerance``.
    """

    runtime: str
    samples: int
    batch_sizes: list[int]
    max_abs_diff: float
    max_abs_diff_targets: float | None
    tolerance: float
    ok: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form (manifest meta, CLI output)."""
        return asdict(self)

    def summary(self) -> str:
        """One human line."""
        text = f"{self.runtime} vs torch actor: max |Δa| = {self.max_abs_diff:.2e}"
        if self.max_abs_diff_targets is not None:
            text += f", max |Δq_target| = {self.max_abs_diff_targets:.2e}"
        verdict = "OK" if self.ok else "FAILED"
        return (
            f"{text} on {self.samples} random inputs, batch sizes {self.batch_sizes} "
            f"(tolerance {self.tolerance:.0e}): {verdict}"
        )


def random_inputs(meta: dict[str, Any], samples: int, seed: int) -> dict[str, np.ndarray]:
    """Random model inputs by the metadata's input list.

    ``history`` ~ N(0, 1) (observations are scaled to order one), ``morphology`` ~ U[-1.2, 1.2] (the training
    support is [-1, 1], a little outside included).

    Returns:
        Input name -> float32 array, e.g. ``history`` (samples, 16, 48).
    """
    gen = torch.Generator().manual_seed(seed)
    out = {}
    for spec in meta["inputs"]:
        shape = (samples, *spec["shape"][1:])
        if spec["name"] == "morphology":
            x = (torch.rand(shape, generator=gen) * 2.0 - 1.0) * 1.2
        else:
            x = torch.randn(shape, generator=gen)
        out[spec["name"]] = x.numpy()
    return out


def reference_outputs(actor: torch.nn.Module, meta: dict[str, Any], inputs: dict[str, np.ndarray]) -> list[np.ndarray]:
    """What the trained actor (and the env's target rule) give for ``inputs``: the export's expected outputs.

    Args:
        actor: The trained :class:`~morfic_cli.rl.models.MorficActor` (eval mode).
        meta: The export metadata (inputs, outputs, baked robot, control section).
        inputs: Model inputs by name.

    Returns:
        One array per metadata output: actions (N, 12) float32; joint_targets (N, 12) float64 (the env computes
        targets in float64).
    """
    history = torch.as_tensor(inputs["history"])
    n = history.shape[0]
    if "morphology" in inputs:
        morphology = torch.as_tensor(inputs["morphology"])
    elif meta["baked_robot"] is not None:
        m = torch.as_tensor(meta["robots"][meta["baked_robot"]]["morphology"], dtype=torch.float32)
        morphology = m.expand(n, -1)
    else:
        morphology = torch.zeros(n, len(meta["descriptor"]["names"]))
    with torch.no_grad():
        actions = actor(TensorDict({"history": history, "morphology": morphology}, batch_size=[n])).numpy()
    outs = [actions]
    if len(meta["outputs"]) > 1:
        robot = meta["robots"][meta["baked_robot"]]
        control = meta["control"]
        clipped = np.clip(actions, -control["action_clip"], control["action_clip"])
        targets = np.asarray(robot["default_joint_pos"]) + control["action_scale"] * clipped
        limits = np.asarray(robot["joint_limits"])
        outs.append(np.clip(targets, limits[:, 0], limits[:, 1]))
    return outs


def verify_outputs(
    runner: Runner,
    runtime: str,
    actor: torch.nn.Module,
    meta: dict[str, Any],
    *,
    samples: int = 256,
    seed: int = 0,
    tolerance: float = TOLERANCE,
) -> Verification:
    """Compare the exported model (through ``runner``) with the trained actor on random inputs.

    Args:
        runner: The loaded export (:func:`~morfic_cli.export.runtime.load_runner`).
        runtime: Name of the runtime, for the record.
        actor: The trained actor (eval mode).
        meta: The export metadata.
        samples: Random inputs (the full batch); the first one is also run alone (batch 1).
        seed: Seed of the random inputs.
        tolerance: Largest accepted absolute difference.
    """
    inputs = random_inputs(meta, samples, seed)
    expected = reference_outputs(actor, meta, inputs)
    got = runner(inputs)
    single = runner({k: v[:1] for k, v in inputs.items()})
    diffs = []
    for i in range(len(expected)):
        if got[i].shape != expected[i].shape or single[i].shape != expected[i][:1].shape:
            diffs.append(float("inf"))
            continue
        full = np.abs(got[i].astype(np.float64) - expected[i]).max()
        one = np.abs(single[i].astype(np.float64) - expected[i][:1]).max()
        diffs.append(float(max(full, one)))
    ok = all(np.isfinite(d) and d < tolerance for d in diffs)
    return Verification(
        runtime, samples, [samples, 1], diffs[0], diffs[1] if len(diffs) > 1 else None, tolerance, bool(ok)
    )


def model_mismatches(meta: dict[str, Any], robot: str, model: mujoco.MjModel) -> list[str]:
    """Differences between the metadata of ``robot`` and its generated MuJoCo model (empty: they agree).

    Checks the actuator order (names and the joints they drive) against ``joint_names``, and Kp, Kd, torque
    limits and joint limits against the position actuators and joints, to 1e-9.
    """
    names = meta["joint_names"]
    section = meta["robots"][robot]
    problems = []
    actuators = [model.actuator(i).name for i in range(model.nu)]
    if actuators != names:
        return [f"{robot}: model actuators {actuators} are not the metadata's joint_names {names}"]
    driven = [model.joint(int(model.actuator_trnid[i, 0])).name for i in range(model.nu)]
    if driven != names:
        problems.append(f"{robot}: the actuators drive {driven}, not joint_names in order")
    joint_ids = [model.joint(n).id for n in names]
    checks = {
        "kp": model.actuator_gainprm[:, 0],
        "kd": -model.actuator_biasprm[:, 2],
        "torque_limit": model.actuator_forcerange[:, 1],
        "joint_limits": model.jnt_range[joint_ids],
    }
    for key, actual in checks.items():
        if not np.allclose(np.asarray(section[key]), actual, rtol=0.0, atol=1e-9):
            problems.append(f"{robot}: metadata {key} {section[key]} differs from the model's {actual.tolist()}")
    return problems
