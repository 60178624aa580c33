"""The offscreen-rendering probe shared by the video tests (run in a subprocess: a GL failure can abort)."""

from __future__ import annotations

import os
import textwrap

PROBE = textwrap.dedent("""
    import mujoco  # before MUJOCO_GL is chosen: render_frames must re-point mujoco at the chosen backend
    import numpy as np
    from morfic_cli.recording.video import render_frames
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><geom type="plane" size="1 1 .1"/><body><freejoint/><geom size=".1"/></body>'
        '</worldbody></mujoco>')
    qpos = np.tile(np.array([0, 0, .2, 1, 0, 0, 0.]), (2, 1, 1))
    frames = render_frames([model], qpos, every=1, width=32, height=24)
    assert frames.shape == (2, 24, 32, 3) and frames.std() > 0, frames.shape
    import os
    print(os.environ["MUJOCO_GL"])
""")


def probe_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("DISPLAY", None)  # headless, like CI
    return env
