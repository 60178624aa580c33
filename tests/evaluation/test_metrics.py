"""Zero-shot metrics on hand-made rollouts, checked against numbers computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from morfic_cli.evaluation.metrics import (
    alive_mask,
    paper_cell,
    per_env_max_moving_average,
    per_env_mean,
    transfer_metrics,
)


def _upright(t: int, n: int) -> dict[str, np.ndarray]:
    return {"tilt": np.zeros((t, n)), "height_ratio": np.ones((t, n)), "foot_slip": np.zeros((t, n))}


def test_an_env_that_dies_at_step_10_does_not_survive_and_only_alive_steps_count():
    t, n = 20, 2
    vx = np.full((t, n), 1.0)
    vx[:, 1] = 2.0
    vx[9:, 1] = 50.0  # env 1 terminates on step 10 (index 9): that step and later are not averaged
    terminated = np.zeros((t, n), dtype=bool)
    terminated[9, 1] = True
    terminated[15, 1] = True  # a later episode of the reset env: ignored
    alive = alive_mask(terminated)
    assert alive[:9, 1].all() and not alive[9:, 1].any() and alive[:, 0].all()
    np.testing.assert_allclose(per_env_mean(vx, alive), [1.0, 2.0])
    m = transfer_metrics(vx, terminated, 1.0, 0.02, **_upright(t, n))
    assert m.survival == 0.5
    assert m.vx_mean == pytest.approx(1.5) and m.vx_env_std == pytest.approx(0.5)  # population std of (1, 2)
    # σ over the 20 + 9 alive (env, step) samples: 20 x 1.0 and 9 x 2.0 -> mean 38/29, var = 20*9/29^2
    assert m.n_alive == 29 and m.vx_step_mean == pytest.approx(38 / 29)
    assert m.vx_std == pytest.approx(math.sqrt(20 * 9) / 29)
    assert m.tracking_ratio == pytest.approx(1.5)
    assert m.valid_fraction == 0.5 and m.valid and m.verdict == "ok"


def test_sigma_is_over_alive_steps_not_over_per_env_means():
    """Hand-made rollout: T = 4, N = 2, env 1 falls on step 3 (index 2).

    env 0: v = 1, 3, 1, 3 (all alive) -> mean 2; env 1: v = 2, 2, (fall) 9, 9 -> alive 2, 2, mean 2.
    Per-env means (2, 2): their std is 0 (the old σ). Alive samples 1, 3, 1, 3, 2, 2: mean 2,
    variance (1 + 1 + 1 + 1 + 0 + 0) / 6 = 2/3 -> σ = 0.8165 (the paper's).
    """
    vx = np.array([[1.0, 2.0], [3.0, 2.0], [1.0, 9.0], [3.0, 9.0]])
    terminated = np.zeros((4, 2), dtype=bool)
    terminated[2, 1] = True
    m = transfer_metrics(vx, terminated, 2.0, 0.02, **_upright(4, 2))
    assert m.vx_mean == pytest.approx(2.0) and m.vx_env_std == pytest.approx(0.0)
    assert m.n_alive == 6 and m.vx_step_mean == pytest.approx(2.0)
    assert m.vx_std == pytest.approx(math.sqrt(2 / 3))
    assert paper_cell(m) == "2.00 ± 0.82 / 0.500"


def test_the_one_second_peak_is_the_best_moving_average():
    dt = 0.25  # window = 4 steps
    vx = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 0.0, 0.0, 0.0])[:, None]
    alive = np.ones_like(vx, dtype=bool)
    # windows of 4: 1.5, 2.5, 2.25, 1.75, 1.0 -> 2.5
    assert per_env_max_moving_average(vx, alive, 4)[0] == pytest.approx(2.5)
    m = transfer_metrics(vx, np.zeros_like(vx, dtype=bool), 2.0, dt, **_upright(8, 1))
    assert m.vx_peak_1s_mean == pytest.approx(2.5) and m.vx_peak_1s_std == 0.0
    assert m.vx_mean == pytest.approx(10.0 / 8)


def test_peak_window_shrinks_to_a_short_alive_span():
    vx = np.array([[1.0], [3.0], [9.0]])
    alive = np.array([[True], [True], [False]])
    assert per_env_max_moving_average(vx, alive, 50)[0] == pytest.approx(2.0)
    assert math.isnan(per_env_max_moving_average(vx, np.zeros_like(alive), 50)[0])


@pytest.mark.parametrize(
    ("change", "verdict"),
    [
        ({"vx": 0.05}, "stands still"),
        ({"height_ratio": 0.3}, "lies down"),
        ({"tilt": 1.2}, "lies down"),
        ({"foot_slip": 0.8}, "drags feet"),
    ],
)
def test_a_survivor_that_does_not_walk_is_not_a_valid_transfer(change, verdict):
    t, n = 50, 4
    arrays = _upright(t, n)
    vx = np.full((t, n), change.get("vx", 1.0))
    for key in ("height_ratio", "tilt", "foot_slip"):
        if key in change:
            arrays[key][:] = change[key]
    m = transfer_metrics(vx, np.zeros((t, n), dtype=bool), 1.0, 0.02, **arrays)
    assert m.survival == 1.0
    assert not m.valid and m.valid_fraction == 0.0 and m.verdict == verdict


def test_paper_cell_format():
    m = transfer_metrics(np.array([[2.0, 2.5]] * 5), np.zeros((5, 2), dtype=bool), 2.0, 0.02, **_upright(5, 2))
    assert paper_cell(m) == "2.25 ± 0.25 / 1.000"  # σ over the 10 samples 2.0 x 5, 2.5 x 5
