"""The eval figure's curves, computed by hand on a 4-step x 3-env rollout."""

from __future__ import annotations

import numpy as np

from morfic_cli.evaluation.figures import rollout_figure, speed_survival


def test_speed_survival_curves_by_hand():
    vx = np.array([[1.0, 2.0, 3.0],
                   [1.0, 2.0, 5.0],
                   [1.0, 4.0, 9.0],
                   [2.0, 4.0, 9.0]], dtype=np.float32)
    terminated = np.zeros((4, 3), bool)
    terminated[1, 2] = True  # env 2 falls at step 1: alive at step 0 only
    terminated[3, 0] = True  # env 0 falls at the last step
    c = speed_survival(vx, terminated, dt=0.5)
    np.testing.assert_allclose(c["t"], [0.5, 1.0, 1.5, 2.0])
    np.testing.assert_allclose(c["mean"], [2.0, 1.5, 2.5, 4.0])  # alive envs: {0,1,2}, {0,1}, {0,1}, {1}
    np.testing.assert_allclose(c["survival"], [1.0, 2 / 3, 2 / 3, 1 / 3])
    np.testing.assert_allclose(sorted(c["fall_t"]), [1.0, 2.0])
    # the band: 10th and 90th percentiles (linear interpolation) of the alive envs
    np.testing.assert_allclose(c["low"][0], 1.2)
    np.testing.assert_allclose(c["high"][1], 1.9)


def test_no_env_alive_leaves_the_speed_undefined_and_the_figure_draws():
    vx = np.ones((3, 2), np.float32)
    terminated = np.array([[True, True], [False, False], [False, False]])
    c = speed_survival(vx, terminated, dt=0.02)
    assert np.isnan(c["mean"]).all() and c["survival"].tolist() == [0.0, 0.0, 0.0]
    png, pdf = rollout_figure(vx, terminated, 0.02, 2.0, "b1, descriptor mode, command 2 m/s")
    assert png.startswith(b"\x89PNG") and pdf.startswith(b"%PDF")
