"""The robot library: loading, the paper's descriptors, masses, conventions and validation errors."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from paper_facts import PAPER_DESCRIPTORS

from morfic_cli.errors import RobotSpecError, UnknownNameError
from morfic_cli.morphology.descriptor import DESCRIPTOR_NAMES
from morfic_cli.morphology.robots import (
    JOINTS,
    LEGS,
    conflict_rows,
    descriptor_rows,
    fact_rows,
    list_robots,
    load_robot,
    load_robot_file,
    robots_dir,
)

ROBOTS = list_robots()
"""Every robot in the library: the generic checks run on each, so a new TOML needs no test edit."""
PAPER_ROBOTS = list(PAPER_DESCRIPTORS)
"""The paper's seven robots, for the checks against the paper's (and public) numbers."""


# The paper's bold up/down marks in the same table (+1 up, -1 down).
PAPER_MARKS = {
    "go2": {"calf_limit_min": -1},
    "go1": {"thigh_limit_min": 1, "thigh_limit_max": 1},
    "a1": {"thigh_limit_min": 1, "thigh_limit_max": 1},
    "mini_cheetah": {"hip_limit_min": -1, "hip_limit_max": 1, "thigh_limit_min": -1, "thigh_limit_max": -1},
    "aliengo": {
        "calf_mass": 1,
        "hip_mass": 1,
        "base_mass": 1,
        "hip_limit_min": -1,
        "hip_limit_max": 1,
        "thigh_limit_min": -1,
        "thigh_limit_max": -1,
        "calf_limit_min": -1,
        "calf_limit_max": 1,
    },
    "anymal_c": {
        "calf_mass": 1,
        "hip_mass": 1,
        "foot_mass": 1,
        "base_mass": 1,
        "hip_limit_min": 1,
        "hip_limit_max": -1,
    },
    "b1": {
        "thigh_mass": 1,
        "calf_mass": 1,
        "hip_mass": 1,
        "base_mass": 1,
        "hip_limit_min": 1,
        "hip_limit_max": -1,
        "thigh_limit_min": 1,
        "calf_limit_max": 1,
    },
}

# Public total masses (the robots' public URDFs; Mini Cheetah with rotors and pkGym feet).
PUBLIC_TOTAL = {
    "go2": 16.09,
    "go1": 11.31,
    "a1": 13.74,
    "aliengo": 24.94,
    "b1": 62.58,
    "mini_cheetah": 8.952,
    "anymal_c": 52.13,
}


def test_library_holds_the_papers_seven_robots_template_first():
    names = list_robots()
    assert set(PAPER_ROBOTS) <= set(names) and len(PAPER_ROBOTS) == 7
    assert names[0] == "go2"


@pytest.mark.parametrize("name", PAPER_ROBOTS)
def test_descriptor_is_the_papers_in_descriptor_order(name):
    spec = load_robot(name)
    assert spec.descriptor.shape == (11,)
    np.testing.assert_allclose(spec.descriptor, PAPER_DESCRIPTORS[name], atol=1e-12)
    rows = descriptor_rows(spec)
    assert [r["name"] for r in rows] == list(DESCRIPTOR_NAMES)
    assert [r["value"] for r in rows] == pytest.approx(PAPER_DESCRIPTORS[name])


@pytest.mark.parametrize("name", PAPER_ROBOTS)
def test_support_flags_reproduce_the_papers_marks(name):
    flags = load_robot(name).support_flags()
    expected = [PAPER_MARKS.get(name, {}).get(n, 0) for n in DESCRIPTOR_NAMES]
    assert flags.tolist() == expected


def test_only_go2_is_the_template():
    assert [n for n in ROBOTS if load_robot(n).is_template] == ["go2"]


def test_go2_total_mass_by_hand():
    # base + 4 x (hip + thigh + calf + foot + three 0.089 kg rotors), unitree_ros go2 URDF.
    expected = 6.921 + 4 * (0.678 + 1.152 + 0.154 + 0.040 + 3 * 0.089)
    assert expected == pytest.approx(16.085)
    assert load_robot("go2").total_mass == pytest.approx(expected, abs=1e-12)


def test_anymal_total_includes_the_twelve_drives_by_hand():
    # base with fixed parts + 4 x (hip_fixed + thigh_fixed + shank_fixed + foot) + 12 ANYdrives.
    expected = 18.213 + 4 * (0.74 + 1.03 + 0.33742 + 0.25) + 12 * 2.04
    assert load_robot("anymal_c").total_mass == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("name", PAPER_ROBOTS)
def test_total_mass_matches_the_public_total(name):
    spec = load_robot(name)
    assert spec.public_total_mass == PUBLIC_TOTAL[name]
    assert spec.total_mass == pytest.approx(PUBLIC_TOTAL[name], rel=2e-3)


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_convention_and_default_pose_inside_limits(name):
    spec = load_robot(name)
    assert spec.joint_range.shape == (4, 3, 2)
    assert spec.default_pose.shape == (4, 3)
    assert np.all(spec.joint_range[..., 0] < spec.joint_range[..., 1])
    assert np.all(spec.default_pose >= spec.joint_range[..., 0])
    assert np.all(spec.default_pose <= spec.joint_range[..., 1])
    # Legs mirror the front-left one: y flips on the right, x on the hind legs.
    signs = {"FL": (1, 1), "FR": (1, -1), "RL": (-1, 1), "RR": (-1, -1)}
    for li, leg in enumerate(LEGS):
        sx, sy = signs[leg]
        assert spec.hip_pos[li, 0] == pytest.approx(sx * spec.hip_pos[0, 0])
        assert spec.hip_pos[li, 1] == pytest.approx(sy * spec.hip_pos[0, 1])


@pytest.mark.parametrize("name", ["go2", "go1", "a1", "aliengo", "b1", "mini_cheetah"])
def test_knee_is_negative_for_unitree_and_mini_cheetah(name):
    assert np.all(load_robot(name).default_pose[:, JOINTS.index("calf")] < 0)


def test_mini_cheetah_signs_are_converted_to_the_plus_y_axis():
    spec = load_robot("mini_cheetah")
    np.testing.assert_allclose(spec.default_pose[:, 1], 0.785398)
    np.testing.assert_allclose(spec.default_pose[:, 2], -1.596976)
    assert spec.base_inertia[1] == pytest.approx(0.036203)  # not the URDF typo 0.36203


def test_anymal_hind_knees_bend_forward_and_haa_limits_are_per_side():
    spec = load_robot("anymal_c")
    front, hind = [LEGS.index(leg) for leg in ("FL", "FR")], [LEGS.index(leg) for leg in ("RL", "RR")]
    np.testing.assert_allclose(spec.default_pose[front, 1:], [[0.4, -0.8]] * 2)
    np.testing.assert_allclose(spec.default_pose[hind, 1:], [[-0.4, 0.8]] * 2)
    np.testing.assert_allclose(spec.joint_range[LEGS.index("FL"), 0], [-0.72, 0.49])
    np.testing.assert_allclose(spec.joint_range[LEGS.index("FR"), 0], [-0.49, 0.72])
    assert spec.rotor_mass.tolist() == [2.04, 2.04, 2.04]
    assert spec.calf_rotor_at == "calf_joint"


def test_go2_rear_thigh_limits_differ_from_the_front():
    spec = load_robot("go2")
    np.testing.assert_allclose(spec.joint_range[LEGS.index("FL"), 1], [-1.5708, 3.4907])
    np.testing.assert_allclose(spec.joint_range[LEGS.index("RR"), 1], [-0.5236, 4.5379])


@pytest.mark.parametrize("name", ROBOTS)
def test_every_fact_has_a_unit_and_a_source(name):
    spec = load_robot(name)
    rows = fact_rows(spec)
    assert len(rows) > 30
    for row in rows:
        assert row["unit"] and row["source"].strip(), row


@pytest.mark.parametrize(
    "name,fields",
    [
        ("go2", ["thigh_limit"]),
        ("aliengo", ["hip_mass", "thigh_limit"]),
        ("mini_cheetah", ["foot_mass", "calf_limit"]),
        ("anymal_c", ["thigh_mass", "hip_limit", "calf_limit"]),
        ("go1", ["base_mass"]),
        ("a1", ["base_mass"]),
    ],
)
def test_conflicts_with_public_sources_are_recorded(name, fields):
    text = " ".join(r["field"] for r in conflict_rows(load_robot(name)))
    for field in fields:
        assert field in text


def test_unknown_robot_lists_the_valid_names():
    with pytest.raises(UnknownNameError, match="valid robots are: a1, aliengo"):
        load_robot("go3")


def test_robots_dir_env_override(tmp_path, monkeypatch):
    (tmp_path / "go2.toml").write_text((robots_dir() / "go2.toml").read_text())
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path))
    assert robots_dir() == tmp_path
    assert list_robots() == ["go2"]
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path / "missing"))
    with pytest.raises(RobotSpecError, match="MORFIC_ROBOTS_DIR"):
        robots_dir()


def test_name_must_match_the_file(tmp_path, monkeypatch):
    (tmp_path / "mygo.toml").write_text((robots_dir() / "go2.toml").read_text())
    monkeypatch.setenv("MORFIC_ROBOTS_DIR", str(tmp_path))
    with pytest.raises(RobotSpecError, match="does not match the file name"):
        load_robot("mygo")


# --------------------------------------------------------------------------------------------------
# bad TOML: every mistake names the file and the field
# --------------------------------------------------------------------------------------------------

GO2_TEXT = (Path(__file__).resolve().parents[2] / "robots" / "go2.toml").read_text()


def _mutate(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    assert old in GO2_TEXT, old
    path = tmp_path / "go2.toml"
    path.write_text(GO2_TEXT.replace(old, new, count))
    return path


def _line(prefix: str) -> str:
    return next(line for line in GO2_TEXT.splitlines() if line.startswith(prefix))


@pytest.mark.parametrize(
    "old,new,field,message",
    [
        ("mass = { value = 0.678", "mass = { value = -0.678", "links.hip.mass", "must be > 0"),
        ("mass = { value = 6.921", "mass = { value = 0.0", "base.mass", "must be > 0"),
        ("hip = { value = [-1.0472, 1.0472]", "hip = { value = [1.0472, -1.0472]", "joint_limits.hip", "min limit"),
        ('mass = { value = 6.921, unit = "kg"', 'mass = { value = 6921.0, unit = "g"', "base.mass", "wrong unit 'g'"),
        ("foot_radius = { value = 0.022", "foot_radius = { value = -0.022", "leg.foot_radius", "must be > 0"),
        (
            'calf = { value = -1.5, unit = "rad"',
            'calf = { value = -0.2, unit = "rad"',
            "default_pose.calf",
            "outside the joint",
        ),
        ("kp = { value = 20.0", "kp = { value = nan", "actuators.kp", "finite"),
        (
            "inertia = { value = [0.02448, 0.098077, 0.107]",
            "inertia = { value = [0.02448, 0.98077, 0.107]",
            "base.inertia",
            "triangle inequality",
        ),
        ("[base]\n", '[base]\ncolour = "red"\n', "base.colour", "unknown key 'colour'"),
        (
            'unit = "kg", source = "unitree_ros go2_description.urdf @d6f13aa, base link" }',
            'unit = "kg", source = "x", tolerance = 0.1 }',
            "base.mass.tolerance",
            "unknown key",
        ),
        ("[descriptor]\n", "[descriptors]\n", "descriptors", "unknown key"),
        ('calf_at = "thigh_joint"', 'calf_at = "knee"', "rotors.calf_at", "not one of"),
        (
            'hip = { left = 0.1, right = -0.1, unit = "rad"',
            'hip = { value = [0.1], unit = "rad"',
            "default_pose.hip",
            "expected a number",
        ),
    ],
)
def test_bad_robot_toml_names_the_field(tmp_path, old, new, field, message):
    path = _mutate(tmp_path, old, new)
    with pytest.raises(RobotSpecError) as info:
        load_robot_file(path)
    text = str(info.value)
    assert str(path) in text
    assert f"field '{field}" in text
    assert message in text


@pytest.mark.parametrize(
    "prefix,field",
    [
        ("foot_radius = ", "leg.foot_radius"),
        ("thigh_limit_max = ", "descriptor"),
        ("init_height = ", "default_pose.init_height"),
    ],
)
def test_missing_field_is_named(tmp_path, prefix, field):
    path = _mutate(tmp_path, _line(prefix) + "\n", "")
    with pytest.raises(RobotSpecError, match=re.escape(field)) as info:
        load_robot_file(path)
    assert "missing" in str(info.value)


def test_missing_table_is_named(tmp_path):
    start = GO2_TEXT.index("[rotors]")
    end = GO2_TEXT.index("[joint_limits]")
    path = tmp_path / "go2.toml"
    path.write_text(GO2_TEXT[:start] + GO2_TEXT[end:])
    with pytest.raises(RobotSpecError, match=r"missing table \[rotors\]"):
        load_robot_file(path)


def test_toml_syntax_error(tmp_path):
    path = _mutate(tmp_path, "[leg]", "[leg")
    with pytest.raises(RobotSpecError, match="TOML syntax error") as info:
        load_robot_file(path)
    assert str(path) in str(info.value)


def test_bad_descriptor_goes_through_as_descriptor(tmp_path):
    path = _mutate(tmp_path, "thigh_limit_min = -1.571", "thigh_limit_min = 5.0")
    with pytest.raises(RobotSpecError, match="thigh_limit_min = 5 is above thigh_limit_max"):
        load_robot_file(path)
    path = _mutate(tmp_path, "base_mass = 6.921", "base_mass = 6921")
    with pytest.raises(RobotSpecError, match="sane range"):
        load_robot_file(path)


def test_unknown_descriptor_key(tmp_path):
    path = _mutate(tmp_path, "base_mass = 6.921", "base_mass = 6.921\nleg_length = 0.4")
    with pytest.raises(RobotSpecError, match="'descriptor.leg_length'"):
        load_robot_file(path)


def test_unreadable_file(tmp_path):
    with pytest.raises(RobotSpecError, match="cannot read"):
        load_robot_file(tmp_path / "nope.toml")
