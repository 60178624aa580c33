"""Report figures a reader can trust: no cut bars, no joined robots, no single dot on log axes, no empty panels."""

from __future__ import annotations

import math

import pytest
from fake_runs import fake_run

from morfic_cli.diagnostics.figures import ev_plot
from morfic_cli.report.figures import compute_plot, curves_plot, distance_plot


@pytest.fixture(autouse=True)
def _close():
    import matplotlib.pyplot as plt

    yield
    plt.close("all")


def test_ev_bars_reach_their_values_on_a_symlog_axis():
    rows = [
        {"run": "r", "variant": "film", "robot": robot, "ev": ev}
        for robot, ev in (("Go2", 0.4), ("B1", -2.713), ("ANYmal-C", -105.815), ("A1", math.nan))
    ]
    ax = ev_plot(rows).axes[0]
    heights = [p.get_height() for p in ax.patches if p.get_width() > 0 and p.get_height() != 0]
    assert heights[:3] == [0.4, -2.713, -105.815]  # drawn to the value, not clipped at -1
    assert ax.get_yscale() == "symlog" and ax.get_ylim()[0] < -105.815
    labels = {t.get_text() for t in ax.texts}
    assert {"0.40", "-2.71", "-105.8", "n/a"} <= labels
    linear = ev_plot([{"run": "r", "variant": "film", "robot": "Go2", "ev": 0.9}]).axes[0]
    assert linear.get_yscale() == "linear"


def test_distance_points_are_not_joined():
    rows = [
        {
            "mode": "descriptor",
            "command_vx": 2.0,
            "d": d,
            "preset": "cpu",
            "variant": "film",
            "robot": robot,
            "vx": vx,
            "vx_std": 0.1,
        }
        for robot, d, vx in (("go2", 0.0, 1.9), ("b1", 0.63, 0.0), ("go1", 0.21, 1.9))
    ]
    ax = distance_plot(rows).axes[0]
    for line in ax.lines:
        if len(line.get_xdata()) > 1 and line.get_linestyle() not in ("None", "none", ""):
            assert len(set(line.get_ydata())) == 1, "only the horizontal command line may be a line"
    assert {"Go2", "B1", "Go1"} <= {t.get_text() for t in ax.texts}


def test_compute_is_bars_and_not_a_lone_log_log_dot():
    rows = [
        {
            "preset": "cpu",
            "variant": "film",
            "device": "cpu",
            "transitions": 12.3e6,
            "device_hours": 1.507,
            "device_hours_400m": 49.0,
        }
    ]
    ax = compute_plot(rows).axes[0]
    (bar,) = [p for p in ax.patches if p.get_width() > 0]
    assert bar.get_width() == 49.0 and ax.get_xscale() == "linear" and not ax.collections
    assert len(compute_plot(rows, with_paper=True).axes[0].patches) > 1


def test_curves_skip_an_all_nan_panel():
    curves = {"film-cpu": [{"env_steps": 1, "mean_reward": 1.0}, {"env_steps": 2, "mean_reward": 2.0}]}
    fig = curves_plot(curves, {"film-cpu": "film"})
    assert [ax.get_title() for ax in fig.axes] == ["mean episode return"]


def test_curves_draw_the_noise_and_the_curriculum_two_panels_a_row():
    rows = [
        {
            "env_steps": s,
            "mean_reward": 1.0 + s,
            "explained_variance": 0.5,
            "action_std": 1.0 - s / 10,
            "curriculum.vx_max": 1.0 + 0.5 * s,
        }
        for s in (0, 1, 2)
    ]
    fig = curves_plot({"adaln-cpu-s0": rows}, {"adaln-cpu-s0": "adaln"})
    assert [ax.get_title() for ax in fig.axes] == [
        "mean episode return",
        "critic explained variance (training)",
        "policy action std (exploration noise)",
        "curriculum: top of the v_x command range (m/s)",
    ]
    assert tuple(fig.get_size_inches()) == (9.0, 6.8)  # 2 x 2
    (line,) = fig.axes[3].get_lines()
    assert list(line.get_ydata()) == [1.0, 1.5, 2.0]
    three = curves_plot({"a": [{k: v for k, v in r.items() if k != "curriculum.vx_max"} for r in rows]}, {"a": "ppo"})
    assert len(three.axes) == 3  # the empty fourth cell is removed


def test_seeds_are_a_mean_and_a_min_max_band_on_the_union_of_their_steps():
    from morfic_cli.report.figures import seed_band

    s0 = [{"env_steps": 0, "r": 0.0}, {"env_steps": 10, "r": 10.0}, {"env_steps": 20, "r": 20.0}]
    s1 = [{"env_steps": 0, "r": 2.0}, {"env_steps": 5, "r": 4.0}, {"env_steps": 10, "r": 6.0}]  # stopped early
    band = seed_band([s0, s1], "r")
    assert band["x"] == [0.0, 5.0, 10.0, 20.0]
    assert band["n"] == [2, 2, 2, 1]
    assert band["mean"] == pytest.approx([1.0, 4.5, 8.0, 20.0])  # s0 at 5 interpolated: 5.0
    assert band["low"] == pytest.approx([0.0, 4.0, 6.0, 20.0]) and band["high"] == pytest.approx([2.0, 5.0, 10.0, 20.0])


def test_curves_draw_one_mean_line_per_variant_and_preset_with_the_legend_off_the_axes():
    def run(offset):
        return [{"env_steps": s, "mean_reward": s + offset} for s in (0, 1, 2)]

    curves = {
        "film-cpu-s0": run(0.0),
        "film-cpu-s1": run(2.0),
        "film-cpu-s2": run(4.0),
        "ppo-cpu-s0": run(1.0),
        "film-smoke-s0": run(9.0),
    }
    variants = {n: n.split("-")[0] for n in curves}
    presets = {n: n.split("-")[1] for n in curves}
    fig = curves_plot(curves, variants, presets)
    (ax,) = fig.axes
    assert len(ax.get_lines()) == 3  # film cpu (mean of 3), ppo cpu, film smoke: never one line per seed
    film = [line for line in ax.get_lines() if list(line.get_ydata()) == [2.0, 3.0, 4.0]]
    assert len(film) == 1 and len(ax.collections) == 1  # the mean, and one band
    assert ax.get_legend() is None and len(fig.legends) == 1  # the legend is the figure's, below the panels
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == [
        "PPO (cpu) (ppo-cpu-s0)",
        "MorFiC-F (cpu): mean of 3 seeds, band min\u2013max",
        "MorFiC-F (smoke) (film-smoke-s0)",
    ]  # the variants' order, presets apart
    assert (
        distance_plot(
            [
                {
                    "mode": "descriptor",
                    "command_vx": 2.0,
                    "d": 0.0,
                    "preset": "cpu",
                    "variant": "film",
                    "robot": "go2",
                    "vx": 1.9,
                    "vx_std": 0.1,
                }
            ]
        )
        .axes[0]
        .get_legend()
        .get_bbox_to_anchor()
    )


def test_filter_presets_keeps_one_preset_and_names_the_others_when_none_match():
    from morfic_cli.errors import MorficError
    from morfic_cli.report.gather import filter_presets

    def info(name, preset):
        return fake_run("film", preset=preset, name=name, checkpoint=name)

    runs = [info("film-cpu-s0", "cpu"), info("film-smoke-s0", "smoke"), info("film-cpu-s1", "cpu")]
    assert [r.name for r in filter_presets(runs, ("cpu",))] == ["film-cpu-s0", "film-cpu-s1"]
    assert filter_presets(runs, ()) == runs
    assert [r.name for r in filter_presets(runs, ("smoke", "cpu"))] == ["film-cpu-s0", "film-smoke-s0", "film-cpu-s1"]
    with pytest.raises(
        MorficError,
        match=r"no run has preset paper; the runs here have: cpu \(2 runs\), "
        r"smoke \(1 run\)",
    ):
        filter_presets(runs, ("paper",))
