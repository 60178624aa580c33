"""Critic diagnostics (docs/metrics.md; paper appendix "Evaluation Metrics and Diagnostic Definitions").

- :mod:`~morfic_cli.diagnostics.returns`: Monte-Carlo returns G_hat and the truncation-safe sample set I_eps.
- :mod:`~morfic_cli.diagnostics.metrics`: EV, NVB, NVE, ASA, Flip and CosGrad as pure tensor functions.
- :mod:`~morfic_cli.diagnostics.samples`: diagnostic rollouts (sampled actions, the models' inputs kept), stored
  as MCAP + ``obs.npz`` and reused by id.
- :mod:`~morfic_cli.diagnostics.scoring`: critic values and actor-loss gradients on stored samples.
- :mod:`~morfic_cli.diagnostics.calibration`: ``morfic diagnose RUN...`` (every run x robot).
- :mod:`~morfic_cli.diagnostics.fixed_rollout`: ``morfic diagnose --fixed-rollout ROBOT`` (one actor, many critics).
- :mod:`~morfic_cli.diagnostics.figures`: the EV figure.

Importing this package imports nothing heavy; see docs/metrics.md for the equations and choices.
"""
