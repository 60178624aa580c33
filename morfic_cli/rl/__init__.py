"""Reinforcement learning: rsl-rl 5.x plug-ins for the MorFiC actor-critic variants.

- :mod:`morfic_cli.rl.models`: ``MorficActor`` and ``MorficCritic`` (rsl-rl ``MLPModel`` subclasses resolved by
  ``class_name``).
- :mod:`morfic_cli.rl.variants`: the variant registry (the paper's seven, a user's class by import path).
- :mod:`morfic_cli.rl.ppo`: ``MorficPPO`` (rsl-rl ``PPO`` plus the adaptation-module regression and the per-update
  critic metrics; their EV is :func:`morfic_cli.diagnostics.metrics.explained_variance`).

Nothing is imported here, so ``import morfic_cli.rl`` stays cheap; import the submodules (they import torch).
"""
