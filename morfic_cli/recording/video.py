"""Offscreen videos of evaluation envs: render recorded qpos trajectories, tile the envs, encode MP4 or GIF.

Pipeline (``morfic eval --video``)::

    frames = render_frames(models, qpos)          # (T, E, nq) -> (F, H_grid, W_grid, 3) uint8
    data, ext = encode_video(frames, fps)         # MP4 (H.264) via imageio-ffmpeg, else an animated GIF
    sheet = frame_grid_png(frames, n=6)           # PNG contact sheet for docs

Rendering is offscreen OpenGL through :class:`mujoco.Renderer`. Which OpenGL platform mujoco uses is the
``MUJOCO_GL`` environment variable (``egl``: headless, hardware on a GPU machine, mesa's llvmpipe in software
otherwise; ``osmesa``: software only; ``glfw``: needs a display). :func:`select_gl_backend` picks one.

Caveat: mujoco reads ``MUJOCO_GL`` once, when ``import mujoco`` runs (``mujoco.rendering.classic.gl_context``,
``mujoco.gl_context`` before mujoco 4), and with it unset chooses GLFW, which fails without a display
(``mujoco.FatalError: an OpenGL platform library has not been loaded ...``). Setting the variable after the import
changes nothing by itself, so :func:`render_frames` also re-points mujoco's context class at the chosen backend
before it creates its first renderer; that works as long as no GL context was created in the process yet. After a
failed GLFW attempt in the same process, creating an EGL context aborted the interpreter (mujoco 4.0.0, mesa 22.3:
``libc++abi: __cxa_guard_acquire detected recursive initialization``), so never retry a different backend in the
same process: set ``MUJOCO_GL`` in the environment of the command instead (``MUJOCO_GL=egl morfic eval ...``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import hashlib
import io
import math
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from morfic_cli.errors import MorficError

if TYPE_CHECKING:
    import mujoco

CAMERA_DISTANCE = 1.4
"""Tracking camera distance from the base, m (frames a 0.3-0.6 m tall quadruped with room to step)."""
CAMERA_AZIMUTH = 120.0
"""Tracking camera azimuth, deg: 90 is a side view from the robot's right with +x (forward) to the right of the
image; 120 turns it into a three-quarter view from the front right."""
CAMERA_ELEVATION = -25.0
"""Tracking camera elevation, deg (negative looks down; at -25 the horizon is just above the image)."""
FAR_CLIP_M = 200.0
"""Far clipping distance of the video camera, m (at least). MuJoCo's default, 50 x the model's extent (~40 m for a
quadruped), cut the floor off below the top of the image when the base was high (a jump, a fall, a tall robot):
black wedges at the top of the frame. At 200 m the floor reaches the image's top edge for a base up to ~2 m high."""
SHADOW_MAP_SIZE = 1024
"""Shadow map size used for rendering (mujoco's default 4096 costs ~5x the frame time in software)."""
FLOOR_GRID_SPACING = 0.5
"""Spacing of the grid lines drawn on the floor, m: a tracking camera needs them to show forward motion."""
FLOOR_GRID_HALF_EXTENT = 5.0
"""The grid covers this far around the tracked body, m."""
FLOOR_GRID_RGBA = (0.55, 0.55, 0.58, 1.0)
"""Grid line colour without shadows."""
FLOOR_GRID_RGBA_SHADOWS = (0.3, 0.3, 0.32, 1.0)
"""Grid line colour with shadows: mujoco's shadow pass lights lines again, this darker colour looks the same."""

GIF_MAX_FPS = 15.0
"""GIFs drop frames down to at most this rate (size)."""
GIF_MAX_SIDE = 480
"""GIF frames are downscaled so that the longer side is at most this many pixels."""
GIF_COLORS = 64
"""Size of the GIF's global palette."""

_VALID_GL = {"linux": ("egl", "osmesa", "glfw", "glx"), "darwin": ("cgl", "glfw"), "win32": ("wgl", "glfw")}
_EGL_LIBS = ("libEGL.so.1", "libEGL.so")
_OSMESA_LIBS = ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")

GL_INSTALL_HINT = (
    "Offscreen rendering needs an OpenGL library. On Debian/Ubuntu install EGL (hardware on a GPU machine, "
    "software llvmpipe otherwise): `apt install libegl1 libgl1-mesa-dri`, then set MUJOCO_GL=egl; "
    "or OSMesa (software): `apt install libosmesa6`, then set MUJOCO_GL=osmesa."
)


# --------------------------------------------------------------------------------------------------
# OpenGL backend
# --------------------------------------------------------------------------------------------------


def _loadable(names: Sequence[str], short: str) -> bool:
    """Whether one of the shared libraries ``names`` (or what ``find_library(short)`` finds) loads."""
    found = ctypes.util.find_library(short)
    for name in (*names, *([found] if found else [])):
        try:
            ctypes.CDLL(name)
        except OSError:
            continue
        return True
    return False


def select_gl_backend() -> str:
    """Choose mujoco's OpenGL platform and set ``MUJOCO_GL`` to it.

    Order: an already set (non-empty) ``MUJOCO_GL``, as it is; else ``egl`` when libEGL loads; else ``osmesa``
    when libOSMesa loads. On macOS and Windows with nothing set: ``cgl`` / ``glfw`` (mujoco's own choice).
    Only the variable is set here; see the module docstring for when mujoco reads it.

    Returns:
        The backend name, lower case (``egl``, ``osmesa``, ``glfw``, ...).

    Raises:
        MorficError: ``MUJOCO_GL`` is set to a value mujoco cannot render with on this platform, or no
            OpenGL library is installed (the message says what to install).
    """
    platform = "linux" if sys.platform.startswith("linux") else sys.platform
    valid = _VALID_GL.get(platform, ("glfw",))
    current = os.environ.get("MUJOCO_GL", "").strip().lower()
    if current:
        if current not in valid:
            raise MorficError(
                f"MUJOCO_GL={current!r} cannot render offscreen videos here; use one of {', '.join(valid)} "
                f"(or unset it to choose automatically). {GL_INSTALL_HINT}"
            )
        backend = current
    elif platform != "linux":
        backend = valid[0]
    elif _loadable(_EGL_LIBS, "EGL"):
        backend = "egl"
    elif _loadable(_OSMESA_LIBS, "OSMesa"):
        backend = "osmesa"
    else:
        raise MorficError(f"no OpenGL library for offscreen rendering was found. {GL_INSTALL_HINT}")
    os.environ["MUJOCO_GL"] = backend
    return backend


def _bind_gl_backend(backend: str) -> None:
    """Point mujoco's renderer at ``backend`` even if ``import mujoco`` ran before ``MUJOCO_GL`` was set.

    :class:`mujoco.Renderer` creates its context from ``gl_context.GLContext``, which ``import mujoco`` fixed from
    the ``MUJOCO_GL`` of that moment. Re-binding it works only before the first GL context of the process.
    """
    try:
        from mujoco.rendering.classic import gl_context  # mujoco >= 4
    except ImportError:
        try:
            from mujoco import gl_context  # mujoco 3.x
        except ImportError:  # pragma: no cover - no renderer in this build of mujoco
            return
    try:
        if backend == "egl":
            from mujoco.egl import GLContext
        elif backend == "osmesa":
            from mujoco.osmesa import GLContext
        elif backend in ("glfw", "glx", "wgl"):
            from mujoco.glfw import GLContext
        else:  # cgl and whatever mujoco chose itself
            return
    except (ImportError, OSError, AttributeError) as exc:
        raise MorficError(
            f"mujoco cannot use MUJOCO_GL={backend}: {exc}. Set MUJOCO_GL in the environment before starting "
            f"(`MUJOCO_GL={backend} morfic ...`) and check PYOPENGL_PLATFORM is unset or {backend}. {GL_INSTALL_HINT}"
        ) from exc
    if getattr(gl_context, "GLContext", None) is not GLContext:
        gl_context.GLContext = GLContext


# --------------------------------------------------------------------------------------------------
# rendering
# --------------------------------------------------------------------------------------------------


def grid_shape(n: int) -> tuple[int, int]:
    """Rows and columns of the tile grid for ``n`` envs: ``floor(sqrt(n))`` rows, as many columns as needed.

    1 -> 1x1, 2 -> 1x2, 3 -> 1x3, 4 -> 2x2, 5-6 -> 2x3, 7-8 -> 2x4, 9 -> 3x3, 16 -> 4x4.
    """
    if n < 1:
        raise MorficError(f"need at least one env to render, got {n}.")
    rows = max(1, math.isqrt(n))
    return rows, math.ceil(n / rows)


def _asset_key(model: mujoco.MjModel) -> tuple[Any, ...]:
    """Models with equal keys can share one renderer.

    A renderer's ``MjrContext`` holds what ``mjr_makeContext`` took from its model: meshes, textures, height
    fields, skins and flexes, and the shadow/fog settings scaled by ``stat.extent``; its ``MjvScene`` is sized
    for the model's counts. Geometry sizes, poses, colours and lights come from the model given to
    ``mjv_updateScene``, so models that differ only there (e.g. a descriptor's link lengths) share.
    """
    digest = hashlib.sha1()
    for arr in (
        model.mesh_vert,
        model.mesh_face,
        model.tex_data,
        model.hfield_data,
        model.mat_texid,
        model.skin_vert,
        model.flex_vert,
    ):
        digest.update(np.ascontiguousarray(arr).tobytes())
    counts = (
        model.nbody,
        model.ngeom,
        model.nsite,
        model.nmesh,
        model.ntex,
        model.nmat,
        model.nhfield,
        model.nskin,
        model.nflex,
        model.nlight,
        model.ncam,
    )
    vis = model.vis
    settings = (
        float(model.stat.extent),
        vis.map.shadowclip,
        vis.map.shadowscale,
        vis.map.fogstart,
        vis.map.fogend,
        tuple(vis.rgba.fog),
        vis.quality.shadowsize,
        vis.quality.offsamples,
    )
    return counts, settings, digest.hexdigest()


def _make_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """A renderer of ``width x height``; enlarges the model's offscreen buffer and caps its shadow map meanwhile."""
    import mujoco

    vis = model.vis
    saved = (vis.global_.offwidth, vis.global_.offheight, vis.quality.shadowsize)
    vis.global_.offwidth = max(saved[0], width)
    vis.global_.offheight = max(saved[1], height)
    vis.quality.shadowsize = min(saved[2], SHADOW_MAP_SIZE)
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # mujoco.FatalError, RuntimeError, ImportError from the GL platform
        backend = os.environ.get("MUJOCO_GL", "")
        headless = " glfw needs a display; headless, use egl or osmesa." if backend in ("glfw", "glx") else ""
        raise MorficError(
            f"offscreen rendering failed with MUJOCO_GL={backend}: {exc}.{headless} {GL_INSTALL_HINT}"
        ) from exc
    finally:
        vis.global_.offwidth, vis.global_.offheight, vis.quality.shadowsize = saved


def _add_floor_grid(scene: mujoco.MjvScene, center: np.ndarray, line_width: float, shadows: bool) -> None:
    """Append grid lines on the floor (z = 0) around ``center`` to the scene (decor only, not in the model)."""
    import mujoco

    spacing, extent = FLOOR_GRID_SPACING, FLOOR_GRID_HALF_EXTENT
    rgba = np.asarray(FLOOR_GRID_RGBA_SHADOWS if shadows else FLOOR_GRID_RGBA, dtype=np.float32)
    z = 5e-3  # above the plane: no z-fighting at grazing angles
    cx, cy = (math.floor(float(c) / spacing) * spacing for c in center[:2])
    ticks = np.arange(-extent, extent + 1e-9, spacing)
    segments = [((cx + t, cy - extent, z), (cx + t, cy + extent, z)) for t in ticks]
    segments += [((cx - extent, cy + t, z), (cx + extent, cy + t, z)) for t in ticks]
    for start, end in segments:
        if scene.ngeom >= scene.maxgeom:
            return
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_LINE, np.zeros(3), np.zeros(3), np.eye(3).ravel(), rgba)
        mujoco.mjv_connector(
            geom,
            mujoco.mjtGeom.mjGEOM_LINE,
            line_width,
            np.asarray(start, dtype=np.float64),
            np.asarray(end, dtype=np.float64),
        )
        scene.ngeom += 1


def _follow_lights(scene: mujoco.MjvScene, center: np.ndarray) -> None:
    """Shift the scene's directional lights horizontally by ``center``.

    A directional light's shadow map covers a region around the light's position; a robot that walks a few
    metres from the origin would leave it (and lose its shadow) without this.
    """
    import mujoco

    directional_type = int(mujoco.mjtLightType.mjLIGHT_DIRECTIONAL) if hasattr(mujoco, "mjtLightType") else -1
    for i in range(scene.nlight):
        light = scene.lights[i]
        if light.headlight:
            continue
        directional = getattr(light, "directional", None)  # mujoco 3.x has a flag, 4.x a type
        if directional is None:
            directional = int(light.type) == directional_type
        if directional:
            light.pos[:2] += center[:2]


def render_frames(
    models: Sequence[mujoco.MjModel],
    qpos: np.ndarray,
    *,
    every: int = 2,
    width: int = 320,
    height: int = 240,
    track_body: str | int = 1,
    shadows: bool = True,
    on_frame: Callable[[], None] | None = None,
) -> np.ndarray:
    """Render recorded trajectories of E envs offscreen and tile them into one image per kept time step.

    Each env has its own model (morphologies may differ) but all share the joint layout (a common ``nq``). For
    time steps ``0, every, 2 * every, ...`` every env's ``qpos`` is set into an ``MjData`` of its model,
    ``mj_forward`` runs, and a free camera tracking ``track_body`` (lookat = its position; distance, azimuth and
    elevation :data:`CAMERA_DISTANCE`, :data:`CAMERA_AZIMUTH`, :data:`CAMERA_ELEVATION`) renders it, with grid
    lines on the floor so that forward motion shows. Env ``e`` is tile ``(e // cols, e % cols)`` of a
    :func:`grid_shape` grid, with white lines between tiles; unused tiles are black. Models with the same assets
    share one renderer (one GL context); renderers are closed before returning.

    Args:
        models: E models, one per env.
        qpos: Trajectories, shape (T, E, nq).
        every: Keep every ``every``-th time step.
        width: Width of one env's tile, px.
        height: Height of one env's tile, px.
        track_body: Body the camera follows, name or id (1: the first body after the world, the robot's base).
        shadows: Render shadows (a 1024 shadow map; in software rendering about 2.5x the frame time).
        on_frame: Called after each rendered frame (all envs' tiles of one kept time step), for a progress bar.

    Returns:
        Frames, uint8, shape (F, rows * height, cols * width, 3) with F = ceil(T / every).

    Raises:
        MorficError: Bad shapes or arguments, an unknown body, or no working OpenGL backend.
    """
    qpos = np.asarray(qpos, dtype=np.float64)
    n_env = len(models)
    if qpos.ndim != 3 or qpos.shape[1] != n_env:
        raise MorficError(f"qpos must have shape (T, E={n_env}, nq), got {qpos.shape}.")
    if qpos.shape[0] < 1:
        raise MorficError("qpos has no time steps to render.")
    if every < 1 or width < 1 or height < 1:
        raise MorficError(f"every, width and height must be positive, got {every}, {width}, {height}.")
    nq = {m.nq for m in models}
    if nq != {qpos.shape[2]}:
        raise MorficError(f"every model must have nq = {qpos.shape[2]} (qpos' last axis), got nq {sorted(nq)}.")

    backend = select_gl_backend()
    import mujoco

    _bind_gl_backend(backend)

    bodies = []
    for m in models:
        try:
            bid = m.body(track_body).id
        except (KeyError, IndexError, ValueError) as exc:
            raise MorficError(f"no body {track_body!r} to track (the model has {m.nbody} bodies).") from exc
        bodies.append(bid)

    rows, cols = grid_shape(n_env)
    steps = np.arange(0, qpos.shape[0], every)
    frames = np.zeros((len(steps), rows * height, cols * width, 3), dtype=np.uint8)
    datas = [mujoco.MjData(m) for m in models]
    option = mujoco.MjvOption()
    line_width = max(1.0, height / 240.0)
    renderers: dict[tuple[Any, ...], mujoco.Renderer] = {}
    zfar = {id(m): (m, m.vis.map.zfar) for m in models}  # mjv_updateScene reads it: set while rendering, restored
    try:
        for m, saved in zfar.values():
            m.vis.map.zfar = max(saved, FAR_CLIP_M / max(float(m.stat.extent), 1e-6))
        env_renderers = []
        for m in models:
            key = _asset_key(m)
            if key not in renderers:
                renderers[key] = _make_renderer(m, width, height)
            env_renderers.append(renderers[key])
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.distance, camera.azimuth, camera.elevation = CAMERA_DISTANCE, CAMERA_AZIMUTH, CAMERA_ELEVATION
        for f, t in enumerate(steps):
            for e, (m, d, renderer) in enumerate(zip(models, datas, env_renderers, strict=True)):
                d.qpos[:] = qpos[t, e]
                mujoco.mj_forward(m, d)
                camera.lookat[:] = d.xpos[bodies[e]]
                scene = renderer.scene
                # the env's own model, so that a shared renderer draws each morphology's geometry
                mujoco.mjv_updateScene(m, d, option, None, camera, mujoco.mjtCatBit.mjCAT_ALL.value, scene)
                scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = shadows
                _follow_lights(scene, d.xpos[bodies[e]])
                _add_floor_grid(scene, d.xpos[bodies[e]], line_width, shadows)
                r, c = divmod(e, cols)
                renderer.render(out=frames[f, r * height : (r + 1) * height, c * width : (c + 1) * width])
            if on_frame is not None:
                on_frame()
    finally:
        for renderer in renderers.values():
            renderer.close()
        for m, saved in zfar.values():
            m.vis.map.zfar = saved
    sep = max(1, width // 320)  # white separators between tiles (drawn over the tiles' edges)
    for c in range(1, cols):
        frames[:, :, c * width - sep : c * width + sep] = 255
    for r in range(1, rows):
        frames[:, r * height - sep : r * height + sep] = 255
    return frames


# --------------------------------------------------------------------------------------------------
# encoding
# --------------------------------------------------------------------------------------------------


def _check_frames(frames: np.ndarray) -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] < 1:
        raise MorficError(f"frames must have shape (F >= 1, H, W, 3), got {frames.shape}.")
    if frames.dtype != np.uint8:
        raise MorficError(f"frames must be uint8, got {frames.dtype}.")
    return frames


def find_ffmpeg() -> str | None:
    """The ffmpeg that ``imageio-ffmpeg`` runs (its bundled binary, or ``IMAGEIO_FFMPEG_EXE`` / PATH), or None.

    None when the ``morfic[video]`` extra (imageio-ffmpeg) is not installed or finds no ffmpeg: videos are GIFs.
    """
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:  # not installed, or installed without a binary and none on PATH
        return None


def _encode_mp4(frames: np.ndarray, fps: float) -> bytes:
    """H.264 MP4 (yuv420p, moov atom first) through ``imageio_ffmpeg.write_frames``, at exactly ``fps``.

    yuv420p needs an even width and height: an odd edge is padded by repeating the last row / column (no
    resampling).
    """
    import imageio_ffmpeg

    n, h, w, _ = frames.shape
    frames = np.pad(frames, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    with tempfile.TemporaryDirectory(prefix="morfic-video-") as tmp:
        out = os.path.join(tmp, "video.mp4")
        writer = imageio_ffmpeg.write_frames(
            out,
            (w + w % 2, h + h % 2),
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            fps=fps,
            codec="libx264",
            quality=None,
            macro_block_size=1,
            ffmpeg_log_level="error",
            output_params=["-crf", "23", "-preset", "medium", "-movflags", "+faststart", "-an"],
        )
        writer.send(None)  # start ffmpeg
        try:
            for frame in frames:
                writer.send(np.ascontiguousarray(frame))
        finally:
            writer.close()
        with open(out, "rb") as fh:
            return fh.read()


def _encode_gif(frames: np.ndarray, fps: float) -> bytes:
    """Animated GIF: at most :data:`GIF_MAX_FPS`, longer side <= :data:`GIF_MAX_SIDE`, one global palette."""
    from PIL import Image

    stride = max(1, math.ceil(fps / GIF_MAX_FPS - 1e-9))
    frames = frames[::stride]
    duration_ms = max(20, round(1000.0 * stride / fps))  # GIF delays are in 10 ms; browsers clamp < 20 ms
    n, h, w, _ = frames.shape
    scale = min(1.0, GIF_MAX_SIDE / max(h, w))
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    images = [Image.fromarray(f) for f in frames]
    if scale < 1.0:
        images = [im.resize(size, Image.Resampling.BILINEAR) for im in images]
    # one palette from up to 8 frames spread over the clip: colours stay put between frames (and compress)
    picks = [images[i] for i in np.unique(np.linspace(0, n - 1, min(n, 8)).round().astype(int))]
    mosaic = Image.new("RGB", (size[0], size[1] * len(picks)))
    for i, im in enumerate(picks):
        mosaic.paste(im, (0, i * size[1]))
    palette = mosaic.quantize(colors=GIF_COLORS, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    indexed = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    buf = io.BytesIO()
    indexed[0].save(
        buf,
        format="GIF",
        save_all=True,
        append_images=indexed[1:],
        duration=duration_ms,
        loop=0,
        optimize=False,
        disposal=1,
    )
    return buf.getvalue()


def encode_video(frames: np.ndarray, fps: float, *, fmt: str = "auto") -> tuple[bytes, str]:
    """Encode frames as an MP4 (H.264, at ``fps``) through imageio-ffmpeg when installed, else an animated GIF (Pillow).

    The MP4 needs the ``morfic[video]`` extra (imageio-ffmpeg, :func:`find_ffmpeg`). The GIF is
    kept small: frames dropped to at most :data:`GIF_MAX_FPS`, downscaled to :data:`GIF_MAX_SIDE`, a
    :data:`GIF_COLORS`-colour global palette without dithering.

    Args:
        frames: uint8 frames, shape (F, H, W, 3).
        fps: Frame rate of ``frames``, Hz.
        fmt: ``auto`` (MP4 if possible, else GIF), ``mp4`` (error without ffmpeg) or ``gif``.

    Returns:
        ``(data, extension)`` with extension ``"mp4"`` or ``"gif"`` (no dot).

    Raises:
        MorficError: Bad frames or fps, an unknown ``fmt``, or ``fmt="mp4"`` without a working ffmpeg.
    """
    frames = _check_frames(frames)
    if not fps > 0:
        raise MorficError(f"fps must be positive, got {fps}.")
    if fmt not in ("auto", "mp4", "gif"):
        raise MorficError(f"unknown video format {fmt!r}; use auto, mp4 or gif.")
    if fmt != "gif":
        if find_ffmpeg() is not None:
            try:
                return _encode_mp4(frames, fps), "mp4"
            except (OSError, RuntimeError) as exc:  # imageio-ffmpeg raises RuntimeError / OSError for ffmpeg errors
                if fmt == "mp4":
                    raise MorficError(f"ffmpeg could not encode the MP4: {exc}") from exc
        elif fmt == "mp4":
            raise MorficError("MP4 needs ffmpeg through imageio-ffmpeg: `pip install 'morfic[video]'`.")
    return _encode_gif(frames, fps), "gif"


def frame_grid_png(frames: np.ndarray, n: int = 6, *, fps: float | None = None, max_width: int = 1600) -> bytes:
    """A PNG contact sheet of ``n`` evenly spaced frames (first and last included), in rows of up to 3.

    Args:
        frames: uint8 frames, shape (F, H, W, 3).
        n: Number of frames on the sheet (fewer if F < n).
        fps: Frame rate of ``frames``; when given each frame is labelled with its time ``t = ... s``.
        max_width: Frames are downscaled so that the sheet is at most this wide, px.

    Returns:
        PNG bytes.
    """
    from PIL import Image, ImageDraw

    frames = _check_frames(frames)
    if n < 1:
        raise MorficError(f"need at least one frame on the sheet, got n={n}.")
    idx = np.unique(np.linspace(0, frames.shape[0] - 1, min(n, frames.shape[0])).round().astype(int))
    cols = min(3, len(idx))
    rows = math.ceil(len(idx) / cols)
    gap = 4
    h, w = frames.shape[1:3]
    scale = min(1.0, (max_width - gap * (cols - 1)) / (cols * w))
    tw, th = max(1, round(w * scale)), max(1, round(h * scale))
    sheet = Image.new("RGB", (cols * tw + gap * (cols - 1), rows * th + gap * (rows - 1)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for k, i in enumerate(idx):
        im = Image.fromarray(frames[i])
        if scale < 1.0:
            im = im.resize((tw, th), Image.Resampling.LANCZOS)
        x, y = (k % cols) * (tw + gap), (k // cols) * (th + gap)
        sheet.paste(im, (x, y))
        if fps:
            label = f"t = {i / fps:.2f} s"
            draw.rectangle(draw.textbbox((x + 4, y + 4), label), fill=(255, 255, 255))
            draw.text((x + 4, y + 4), label, fill=(0, 0, 0))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG", optimize=True)
    return buf.getvalue()
