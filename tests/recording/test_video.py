"""Offscreen videos: GL backend choice, tiled frames of Go2 envs, GIF/MP4 encoding and the PNG contact sheet.

Rendering needs an OpenGL library (EGL or OSMesa); without one the rendering tests skip with the reason.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest
from gl_probe import PROBE, probe_env

from morfic_cli.errors import MorficError
from morfic_cli.morphology.builder import build_model
from morfic_cli.morphology.robots import load_robot
from morfic_cli.recording import video
from morfic_cli.recording.video import encode_video, frame_grid_png, grid_shape, render_frames, select_gl_backend

W, H = 64, 48
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def go2():
    return build_model(load_robot("go2"))


def _walk(model: mujoco.MjModel, n_env: int = 2, steps: int = 6, dx: float = 0.1) -> np.ndarray:
    """(steps, n_env, nq): the home pose with the base moving forward ``dx`` per step."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    qpos = np.tile(data.qpos, (steps, n_env, 1))
    qpos[:, :, 0] += dx * np.arange(steps)[:, None]
    return qpos


# --------------------------------------------------------------------------------------------------
# backend choice (no rendering)
# --------------------------------------------------------------------------------------------------


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux backends")
def test_select_respects_mujoco_gl(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "OSMesa")
    assert select_gl_backend() == "osmesa"
    assert os.environ["MUJOCO_GL"] == "osmesa"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux backends")
def test_select_prefers_egl_then_osmesa(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "")
    monkeypatch.setattr(video, "_loadable", lambda names, short: True)
    assert select_gl_backend() == "egl"
    assert os.environ["MUJOCO_GL"] == "egl"
    monkeypatch.setenv("MUJOCO_GL", "")
    monkeypatch.setattr(video, "_loadable", lambda names, short: short == "OSMesa")
    assert select_gl_backend() == "osmesa"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux backends")
def test_select_without_gl_says_what_to_install(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "")
    monkeypatch.setattr(video, "_loadable", lambda names, short: False)
    with pytest.raises(MorficError, match="libosmesa6") as info:
        select_gl_backend()
    assert "libegl1 libgl1-mesa-dri" in str(info.value) and "MUJOCO_GL" in str(info.value)


def test_select_rejects_bad_mujoco_gl(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "disable")
    with pytest.raises(MorficError, match="MUJOCO_GL"):
        select_gl_backend()


def test_grid_shape():
    assert [grid_shape(n) for n in (1, 2, 3, 4, 6, 8, 9)] == [(1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (2, 4), (3, 3)]


def test_render_validates_shapes(go2):
    qpos = _walk(go2)
    with pytest.raises(MorficError, match="shape"):
        render_frames([go2], qpos)  # 2 envs of qpos, 1 model
    with pytest.raises(MorficError, match="nq"):
        render_frames([go2, go2], qpos[:, :, :-1])
    with pytest.raises(MorficError, match="positive"):
        render_frames([go2, go2], qpos, every=0)


# --------------------------------------------------------------------------------------------------
# rendering
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def frames(gl_backend, go2):
    return render_frames([go2, go2], _walk(go2), every=1, width=W, height=H)


def test_frames_tile_the_envs(frames):
    rows, cols = grid_shape(2)
    assert frames.shape == (6, rows * H, cols * W, 3)
    assert frames.dtype == np.uint8


def test_robot_visible_and_moving(frames):
    for tile in (frames[:, :, :W], frames[:, :, W:]):
        assert tile.reshape(len(tile), -1).std(axis=1).min() > 0
    # the camera tracks the base; the floor grid moves under it
    for a, b in zip(frames[:-1], frames[1:], strict=True):
        assert np.any(a != b)
    # same robot, same pose: the two tiles match (apart from the separator at their shared edge)
    assert np.array_equal(frames[:, :, 2 : W - 2], frames[:, :, W + 2 : 2 * W - 2])


def test_every_keeps_every_nth_step(gl_backend, go2):
    qpos = _walk(go2, n_env=1)
    fewer = render_frames([go2], qpos, every=2, width=W, height=H)
    all_ = render_frames([go2], qpos, every=1, width=W, height=H)
    assert fewer.shape == (3, H, W, 3)
    assert np.array_equal(fewer, all_[::2])


def test_each_env_renders_its_own_morphology(gl_backend, go2, monkeypatch):
    """Models that differ only in geometry sizes share one renderer; each tile still shows its own geometry."""
    thick = build_model(load_robot("go2"))
    thick.geom_size[
        [mujoco.mj_name2id(thick, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_calf_geom") for leg in ("FL", "FR", "RL", "RR")], 0
    ] *= 3.0
    made = []
    make = video._make_renderer
    monkeypatch.setattr(video, "_make_renderer", lambda *a: made.append(a[0]) or make(*a))
    qpos = _walk(go2, steps=1)
    both = render_frames([go2, thick], qpos, every=1, width=W, height=H)
    assert made == [go2]
    alone = render_frames([thick], qpos[:, :1], every=1, width=W, height=H)
    assert not np.array_equal(both[0, :, 2 : W - 2], both[0, :, W + 2 : 2 * W - 2])
    assert np.array_equal(both[0, :, W + 2 :], alone[0, :, 2:])


def test_different_robots(gl_backend, go2):
    a1 = build_model(load_robot("a1"))
    both = render_frames([go2, a1], _walk(go2, steps=1), every=1, width=W, height=H)
    assert not np.array_equal(both[0, :, 2 : W - 2], both[0, :, W + 2 : 2 * W - 2])


def test_a_raised_base_shows_floor_up_to_the_top_edge(gl_backend, go2):
    """The floor is not clipped by the far plane (black wedges at the top) with the base 1.5-2 m up; zfar restored."""
    qpos = _walk(go2, n_env=1, steps=2)
    qpos[:, 0, :3] = [[30.0, -10.0, 1.5], [30.0, -10.0, 2.0]]  # a jump far from the origin
    zfar = go2.vis.map.zfar
    frames = render_frames([go2], qpos, every=1, width=320, height=240)
    assert go2.vis.map.zfar == zfar
    top = frames[:, :24]  # the top tenth: far floor, no background (black) wherever it is
    assert int((top.sum(axis=-1) < 30).sum()) == 0  # 1,600 and 3,326 black pixels with mujoco's default far plane


def test_on_frame_counts_the_rendered_frames(gl_backend, go2):
    calls = []
    render_frames([go2], _walk(go2, n_env=1, steps=5), every=2, width=W, height=H, on_frame=lambda: calls.append(1))
    assert len(calls) == 3  # steps 0, 2, 4


def test_unknown_track_body(gl_backend, go2):
    with pytest.raises(MorficError, match="no body"):
        render_frames([go2], _walk(go2, n_env=1), track_body="tail")


def test_renders_after_mujoco_was_imported_without_mujoco_gl():
    """The caveat: ``import mujoco`` with MUJOCO_GL unset picks GLFW; render_frames must still work headless."""
    env = probe_env()
    env.pop("MUJOCO_GL", None)
    proc = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300, check=False
    )
    if proc.returncode != 0 and "OpenGL" in proc.stderr and "MorficError" in proc.stderr:
        pytest.skip("no OpenGL library here: " + proc.stderr.strip().splitlines()[-1])
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] in ("egl", "osmesa")


# --------------------------------------------------------------------------------------------------
# encoding (synthetic frames, no rendering)
# --------------------------------------------------------------------------------------------------


def _synthetic(n: int = 12, h: int = H, w: int = 2 * W) -> np.ndarray:
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, size=(1, h, w, 3), dtype=np.uint8)
    return np.stack([np.roll(base[0], 3 * i, axis=1) for i in range(n)])


def test_gif_fallback(monkeypatch):
    from PIL import Image

    monkeypatch.setattr(video, "find_ffmpeg", lambda: None)
    data, ext = encode_video(_synthetic(), fps=25.0)
    assert ext == "gif" and data[:6] == b"GIF89a"
    im = Image.open(io.BytesIO(data))
    assert im.size == (2 * W, H)
    assert im.n_frames == 6  # 25 fps -> every 2nd frame (at most 15 fps)


def test_gif_forced_and_downscaled():
    from PIL import Image

    big = np.zeros((3, 480, 1280, 3), dtype=np.uint8)
    for i in range(3):  # distinct frames (Pillow merges identical consecutive frames)
        big[i, 100:200, 100 + 50 * i : 300 + 50 * i] = 200
    data, ext = encode_video(big, fps=10.0, fmt="gif")
    assert ext == "gif" and data[:6] == b"GIF89a"
    im = Image.open(io.BytesIO(data))
    assert max(im.size) == video.GIF_MAX_SIDE and im.n_frames == 3


@pytest.mark.skipif(video.find_ffmpeg() is None, reason="no imageio-ffmpeg (pip install 'morfic[video]')")
def test_mp4_through_imageio_ffmpeg_has_the_requested_fps_and_frames(tmp_path):
    import imageio_ffmpeg

    frames = _synthetic(h=47, w=63)  # odd size: padded to even for yuv420p
    data, ext = encode_video(frames, fps=25.0)
    assert ext == "mp4" and data[4:8] == b"ftyp"
    path = tmp_path / "v.mp4"
    path.write_bytes(data)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    decoded = list(reader)
    assert meta["fps"] == pytest.approx(25.0) and tuple(meta["size"]) == (64, 48)
    assert len(decoded) == len(frames)


def test_mp4_without_ffmpeg_is_an_error(monkeypatch):
    monkeypatch.setattr(video, "find_ffmpeg", lambda: None)
    with pytest.raises(MorficError, match="ffmpeg"):
        encode_video(_synthetic(), fps=25.0, fmt="mp4")


def test_encode_validates():
    with pytest.raises(MorficError, match="uint8"):
        encode_video(_synthetic().astype(np.float32), fps=25.0)
    with pytest.raises(MorficError, match="fps"):
        encode_video(_synthetic(), fps=0.0)
    with pytest.raises(MorficError, match="shape"):
        encode_video(_synthetic()[0], fps=25.0)


def test_frame_grid_png():
    from PIL import Image

    frames = _synthetic(n=20)
    data = frame_grid_png(frames, n=6, fps=25.0)
    assert data[:8] == PNG_MAGIC
    im = Image.open(io.BytesIO(data))
    assert im.size == (3 * 2 * W + 2 * 4, 2 * H + 4)  # 3 x 2 frames, 4 px gaps
    assert frame_grid_png(frames[:2], n=6)[:8] == PNG_MAGIC  # fewer frames than n


def test_rendered_video_and_sheet(frames):
    data, ext = encode_video(frames, fps=25.0)
    assert (ext, data[:6]) == ("gif", b"GIF89a") or (ext, data[4:8]) == ("mp4", b"ftyp")
    assert frame_grid_png(frames, n=4)[:8] == PNG_MAGIC
