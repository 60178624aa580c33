"""Names of an evaluation's stored pieces: rollout roles, figure files, media file stems.

The one home of these names, below :mod:`~morfic_cli.evaluation.figures`, :mod:`~morfic_cli.evaluation.protocol`
and :mod:`~morfic_cli.evaluation.media`, which all read them (so none of the three imports another for a name).
"""

from __future__ import annotations

FIGURE_PNG, FIGURE_PDF = "speed.png", "speed.pdf"
"""Files of a rollout manifest with its figure (forward speed and survival over time)."""


def rollout_role(robot: str, mode: str, command_vx: float) -> str:
    """Input role of a rollout manifest, e.g. ``rollout/go1/descriptor/vx2.0``."""
    return f"rollout/{robot}/{mode}/vx{command_vx:g}"


def media_name(role: str) -> str:
    """File stem of a rollout's media: ``rollout/go1/descriptor/vx2`` -> ``go1-descriptor-vx2``."""
    return role.removeprefix("rollout/").replace("/", "-")
