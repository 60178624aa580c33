"""Deployable policies: ONNX / TorchScript export of the actor path with the metadata a robot stack needs.

- :mod:`~morfic_cli.export.policy`: the deployed actor path (adaptation module + morphology encoder + actor,
  observation normaliser included) as torch modules with named inputs.
- :mod:`~morfic_cli.export.metadata`: ``policy.json`` (joint order, gains, limits, observation layout, ...).
- :mod:`~morfic_cli.export.runtime`: serialise to ONNX / TorchScript and run the bytes again.
- :mod:`~morfic_cli.export.verify`: runtime vs torch actor; metadata vs the robots' MuJoCo models.
- :mod:`~morfic_cli.export.artifact`: ``morfic export`` and ``--check`` on the artifact store.

``examples/deploy_loop.py`` is the 50 Hz control loop that consumes an export (docs/deploy.md).
One package rather than one module: model, metadata, runtimes and store glue are separate concerns, and the
metadata builder is used without torch export machinery by the checks.
"""
