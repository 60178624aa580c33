"""A training run as the report reads it, without a store: :class:`RunInfo` rows for the report's unit tests."""

from __future__ import annotations

from morfic_cli.report.gather import RunInfo


def fake_run(variant: str = "film", seed: int = 0, preset: str = "cpu", **fields) -> RunInfo:
    """``runs/<variant>-<preset>-s<seed>``: one finished iteration of one step, 1 s on the cpu; ``fields`` override."""
    name = fields.pop("name", f"{variant}-{preset}-s{seed}")
    values = {
        "spec": f"runs/{name}",
        "name": name,
        "checkpoint": f"{variant}{seed}",
        "variant": variant,
        "seed": seed,
        "preset": preset,
        "iteration": 1,
        "max_iterations": 1,
        "env_steps": 1,
        "wall_time_s": 1.0,
        "device": "cpu",
        "finished": True,
        "created": "",
    }
    return RunInfo(**{**values, **fields})
