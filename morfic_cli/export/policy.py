"""The deployed actor path as a self-contained torch module, ready for ONNX and TorchScript.

The core is :meth:`MorficActor.as_onnx` (rsl-rl's export pattern): a copy of the observation normaliser, the
adaptation module, the morphology encoder and the policy MLP, returning the distribution mean. Here it gets
named inputs instead of one flat vector:

- :class:`DescriptorInputPolicy`: ``(history (N, H, 48), morphology (N, 11)) -> actions (N, 12)``;
- :class:`FixedDescriptorPolicy`: ``history (N, H, 48) -> actions (N, 12)``, the normalised descriptor of one
  robot stored as a buffer (``--robot``; also used for ``ppo``, whose actor has no morphology input);
- :class:`JointTargetPolicy`: as the fixed one, plus ``joint_targets (N, 12)`` by the env's rule
  ``clamp(q0 + action_scale * clip(a, -action_clip, action_clip), q_min, q_max)`` (``--targets``).

No dropout (eval copies) and no sampling: the output is what ``morfic eval`` applies.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch
import torch.nn as nn

if TYPE_CHECKING:
    from rsl_rl.models import MLPModel  # morfic's actors and the external baselines' (rl/models.py, rl/external.py)


def _core(actor: MLPModel) -> nn.Module:
    core = actor.as_onnx()
    core.eval()
    return core


class DescriptorInputPolicy(nn.Module):
    """``(history, morphology) -> actions``. Shapes: (N, H, 48), (N, 11) -> (N, 12)."""

    def __init__(self, actor: MLPModel) -> None:
        super().__init__()
        self.core = _core(actor)

    def forward(self, history: torch.Tensor, morphology: torch.Tensor) -> torch.Tensor:
        """Actions (policy mean). Shape: (N, 12)."""
        return self.core(torch.cat([history.flatten(1), morphology], dim=1))


class FixedDescriptorPolicy(nn.Module):
    """``history -> actions`` with one robot's normalised descriptor built in. Shape: (N, H, 48) -> (N, 12).

    Args:
        actor: The trained actor (eval mode).
        morphology: The normalised descriptor to bake in, shape (11,); ignored (None allowed) when the actor has
            no morphology encoder (variant ``ppo``).
    """

    if TYPE_CHECKING:  # for mypy only: TorchScript cannot read this module's string annotations
        morphology: torch.Tensor  # buffer, (1, 11) or (1, 0)

    def __init__(self, actor: MLPModel, morphology: np.ndarray | None) -> None:
        super().__init__()
        self.core = _core(actor)
        self.uses_morphology = actor.morphology_encoder is not None
        m = torch.as_tensor(morphology, dtype=torch.float32).reshape(1, -1) if self.uses_morphology else None
        self.register_buffer("morphology", m if m is not None else torch.zeros(1, 0))

    def forward(self, history: torch.Tensor) -> torch.Tensor:
        """Actions (policy mean). Shape: (N, 12)."""
        x = history.flatten(1)
        if self.uses_morphology:
            x = torch.cat([x, self.morphology.expand(x.shape[0], -1)], dim=1)
        return self.core(x)


class JointTargetPolicy(nn.Module):
    """``history -> (actions, joint_targets)``: a :class:`FixedDescriptorPolicy` plus the env's target rule.

    Args:
        policy: The fixed-descriptor policy.
        default_joint_pos: q0 (rad). Shape: (12,).
        joint_limits: (min, max) per joint (rad). Shape: (12, 2).
        action_scale: Target = q0 + action_scale * a.
        action_clip: Actions are clipped to [-action_clip, action_clip] first.
    """

    if TYPE_CHECKING:  # for mypy only: TorchScript cannot read this module's string annotations
        default_joint_pos: torch.Tensor  # buffers, (1, 12) rad
        joint_min: torch.Tensor
        joint_max: torch.Tensor

    def __init__(
        self,
        policy: FixedDescriptorPolicy,
        default_joint_pos: np.ndarray,
        joint_limits: np.ndarray,
        action_scale: float,
        action_clip: float,
    ) -> None:
        super().__init__()
        self.policy = policy
        self.action_scale = float(action_scale)
        self.action_clip = float(action_clip)
        limits = torch.as_tensor(np.asarray(joint_limits), dtype=torch.float32)
        self.register_buffer("default_joint_pos", torch.as_tensor(default_joint_pos, dtype=torch.float32)[None])
        self.register_buffer("joint_min", limits[:, 0][None].clone())
        self.register_buffer("joint_max", limits[:, 1][None].clone())

    def forward(self, history: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(actions, joint_targets)``. Shapes: (N, 12), (N, 12) rad."""
        actions = self.policy(history)
        clipped = torch.clamp(actions, -self.action_clip, self.action_clip)
        targets = self.default_joint_pos + self.action_scale * clipped
        targets = torch.maximum(torch.minimum(targets, self.joint_max), self.joint_min)
        return actions, targets
