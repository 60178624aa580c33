"""The 11-D descriptor and eq. (morph_dist), checked against hand-computed numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from morfic_cli.errors import DescriptorError
from morfic_cli.morphology.descriptor import (
    DESCRIPTOR_NAMES,
    TRAIN_MAX,
    TRAIN_MIN,
    as_descriptor,
    distance_bounds,
    morph_distance,
    normalize,
    sample_uniform,
    support_flags,
)


def test_names_are_the_papers_order():
    assert DESCRIPTOR_NAMES == (
        "thigh_mass",
        "calf_mass",
        "hip_mass",
        "foot_mass",
        "base_mass",
        "hip_limit_min",
        "hip_limit_max",
        "thigh_limit_min",
        "thigh_limit_max",
        "calf_limit_min",
        "calf_limit_max",
    )
    # Paper table "Morphology randomization parameters": Train min/max of base mass and calf limit max.
    assert TRAIN_MIN[4] == 3.300 and TRAIN_MAX[4] == 6.921
    assert TRAIN_MIN[10] == -0.950 and TRAIN_MAX[10] == -0.780


def test_support_corners_are_distance_one_and_midpoint_one_half():
    bounds = distance_bounds([TRAIN_MIN, TRAIN_MAX], "support")
    # every normalised coordinate differs by 1: sqrt(11 * 1^2) / sqrt(11) = 1
    assert morph_distance(TRAIN_MAX, TRAIN_MIN, bounds) == pytest.approx(1.0)
    # midpoint: every coordinate differs by 0.5: sqrt(11 * 0.25) / sqrt(11) = 0.5
    assert morph_distance((TRAIN_MIN + TRAIN_MAX) / 2, TRAIN_MIN, bounds) == pytest.approx(0.5)


def test_span_versus_support_by_hand():
    # target = TRAIN_MIN except thigh mass 1.670 (0.518 above the support max 1.152; span 0.518).
    target = TRAIN_MIN.copy()
    target[0] = 1.670
    # span: thigh bounds become [0.634, 1.670] -> normalised diff (1.670-0.634)/1.036 = 1 -> d = 1/sqrt(11)
    span = distance_bounds([TRAIN_MIN, target], "span")
    assert morph_distance(target, TRAIN_MIN, span) == pytest.approx(1 / math.sqrt(11))  # 0.301511
    # support: thigh bounds [0.634, 1.152] -> diff (1.670-0.634)/0.518 = 2 -> d = 2/sqrt(11)
    support = distance_bounds([TRAIN_MIN, target], "support")
    assert morph_distance(target, TRAIN_MIN, support) == pytest.approx(2 / math.sqrt(11))  # 0.603023


def test_distance_is_symmetric_zero_on_self_and_in_unit_interval_for_span():
    rng = np.random.default_rng(0)
    a, b = sample_uniform(2, rng)
    far = TRAIN_MAX * np.array([5, 5, 5, 5, 5, 1, 1, 1, 1, 1, 1])
    bounds = distance_bounds([a, b, far], "span")
    assert morph_distance(a, a, bounds) == 0.0
    assert morph_distance(a, b, bounds) == pytest.approx(morph_distance(b, a, bounds))
    assert 0.0 <= morph_distance(far, a, bounds) <= 1.0


def test_normalize_zero_span_dimension_is_zero():
    lo = np.zeros(11)
    hi = np.ones(11)
    hi[3] = 0.0
    m = np.full(11, 0.25)
    out = normalize(m, lo, hi)
    assert out[3] == 0.0 and out[0] == 0.25


def test_support_flags_match_paper_marks_for_b1():
    b1 = np.array([4.300, 1.050, 2.150, 0.050, 29.450, -0.750, 0.750, -1.000, 3.500, -2.600, -0.600])
    flags = support_flags(b1)
    # Paper: B1 thigh, calf, hip, base mass up; hip limit min up, hip max down; thigh min up; calf max up.
    assert flags.tolist() == [1, 1, 1, 0, 1, 1, -1, 1, 0, 0, 1]


def test_samples_stay_in_support_and_keep_limits_ordered():
    s = sample_uniform(1000, np.random.default_rng(1))
    assert s.shape == (1000, 11)
    assert np.all(s >= TRAIN_MIN) and np.all(s <= TRAIN_MAX)
    assert np.all(s[:, 5] < s[:, 6]) and np.all(s[:, 7] < s[:, 8]) and np.all(s[:, 9] < s[:, 10])


@pytest.mark.parametrize(
    "bad, needle",
    [
        ([1.0] * 10, "expected 11"),
        ([1.0, 0.1, 0.6, 0.05, -3.0, -1, 1, -1, 3.5, -2.7, -0.9], "base_mass"),
        ([1.0, 0.1, 0.6, 0.05, 5.0, 1.0, -1.0, -1, 3.5, -2.7, -0.9], "min limit"),
        ([1.0, 0.1, 0.6, 0.05, float("nan"), -1, 1, -1, 3.5, -2.7, -0.9], "finite"),
        ({"thigh_mass": 1.0}, "missing"),
    ],
)
def test_bad_descriptors_are_rejected_with_a_reason(bad, needle):
    with pytest.raises(DescriptorError, match=needle):
        as_descriptor(bad)
