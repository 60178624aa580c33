"""Videos of evaluation rollouts (``morfic eval --video``) and the files ``morfic eval --out`` copies out.

Videos are rendered, encoded, stored, and written next to ``--out``; :func:`write_logs` copies the MCAP rollout
logs there.

Each rollout that kept its first envs' models (``keep_models``) becomes one ``media`` manifest holding
``video.mp4`` (or ``video.gif`` without ffmpeg) and ``frames.png`` (a contact sheet of six frames), with inputs
``rollout`` (the rollout's MCAP manifest) and ``eval``. Rendering is :mod:`morfic_cli.recording.video`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from morfic_cli.evaluation.names import media_name
from morfic_cli.evaluation.protocol import EvalResult
from morfic_cli.store import Store

ROLLOUT_LOG = "rollout.mcap"
"""The MCAP log's file name in a ``rollout`` manifest."""

VIDEO_EVERY = 2
"""Render every second policy step: 25 frames per second of a 50 Hz policy."""

VIDEO_ENVS = 4
"""Envs shown in a video (the first ones; a rollout may keep more models for its 3D scene)."""


def write_logs(store: Store, eval_id: str, out: Path) -> list[Path]:
    """Copy the MCAP rollout log of every rollout of eval ``eval_id`` into the ``--out`` directory.

    Names: ``<robot>-<mode>-vx<cmd>.mcap`` (beside that rollout's figure and video), each the stored
    ``rollout.mcap`` byte for byte, ready for Foxglove or ``mcap info``.

    Args:
        store: The store the eval is in.
        eval_id: The ``eval`` manifest's id.
        out: The directory (exists).

    Returns:
        The paths written.
    """
    written = []
    for role, rid in store.read_manifest(eval_id).inputs.items():
        if role.startswith("rollout/") and ROLLOUT_LOG in store.read_manifest(rid).files:
            path = out / f"{media_name(role)}.mcap"
            path.write_bytes(store.read_file(rid, ROLLOUT_LOG))
            written.append(path)
    return written


def video_frames(result: EvalResult, every: int = VIDEO_EVERY) -> int:
    """How many frames :func:`store_videos` renders for ``result``: ceil(steps / every) per rollout with models."""
    return sum(math.ceil(r.arrays["done"].shape[0] / every) for r in result.rollouts.values() if r.models)


def store_videos(
    store: Store,
    result: EvalResult,
    out: Path | None,
    *,
    every: int = VIDEO_EVERY,
    on_video: Callable[[str], None] | None = None,
    on_frame: Callable[[], None] | None = None,
) -> list[Path | str]:
    """Render every rollout of ``result`` that kept models, store each as a ``media`` manifest.

    Args:
        store: The store ``result`` was written to.
        result: What :func:`~morfic_cli.evaluation.protocol.evaluate` returned (with ``keep_models`` > 0).
        out: The ``--out`` directory; the videos and frame grids are also written into it as
            ``<robot>-<mode>-vx<cmd>.<mp4|gif>`` and ``...-frames.png``.
        every: Keep every ``every``-th policy step.
        on_video: Called with a rollout's media name (``go1-descriptor-vx2``) before its video is rendered.
        on_frame: Called after each rendered frame (:func:`video_frames` calls in all), for a progress bar.

    Returns:
        The written paths when ``out`` is given, else the media manifest ids.

    Raises:
        MorficError: No working OpenGL backend (with the packages to install).
    """
    from morfic_cli.recording.video import encode_video, frame_grid_png, render_frames

    inputs = store.read_manifest(result.id).inputs
    written: list[Path | str] = []
    for role, rollout in result.rollouts.items():
        if not rollout.models:
            continue
        models = rollout.models[:VIDEO_ENVS]
        if on_video is not None:
            on_video(media_name(role))
        frames = render_frames(models, rollout.qpos(len(models)), every=every, on_frame=on_frame)
        fps = 1.0 / (rollout.dt * every)
        data, ext = encode_video(frames, fps)
        sheet = frame_grid_png(frames, n=6, fps=fps)
        mid = store.publish(
            "media",
            config={"every": every, "fps": fps, "num_envs": len(models)},
            inputs={"rollout": inputs[role], "eval": result.id},
            files={f"video.{ext}": data, "frames.png": sheet},
            meta={"robot": rollout.robot, "mode": rollout.mode, "command_vx": rollout.command_vx},
        ).id
        if out is None:
            written.append(mid)
            continue
        out.mkdir(parents=True, exist_ok=True)
        stem = out / media_name(role)
        video_path, sheet_path = stem.with_name(stem.name + f".{ext}"), stem.with_name(stem.name + "-frames.png")
        video_path.write_bytes(data)
        sheet_path.write_bytes(sheet)
        written += [video_path, sheet_path]
    return written
