"""The robot library: load and validate ``robots/<name>.toml`` into a typed :class:`RobotSpec`.

Every physical fact in a robot TOML is an inline table with its value, its unit and its source::

    mass = { value = 6.921, unit = "kg", source = "unitree_ros go2_description.urdf @d6f13aa" }

Leg geometry is written for the front-left (FL) leg and mirrored: ``y -> -y`` for the right legs
(FR, RR) and ``x -> -x`` for the hind legs (RL, RR). Facts that differ between legs (joint limits,
default pose) may be written per side, ``{ front = .., rear = .. }`` or ``{ left = .., right = .. }``,
instead of ``{ value = .. }``.

Joint convention (every robot): hip abduction about +x, thigh and calf about +y, with all joint
frames aligned with the base frame at zero angle. A positive thigh angle swings the foot backwards;
the knee angle is negative for a backward-bending knee (Unitree, Mini Cheetah, ANYmal-C front legs)
and positive for ANYmal-C's forward-bending hind knees (X configuration).

This module does not import mujoco; :mod:`morfic_cli.morphology.builder` turns a spec into a model.
See ``docs/robots.md`` for the schema and the facts.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from morfic_cli.errors import DescriptorError, RobotSpecError, UnknownNameError
from morfic_cli.morphology.descriptor import (
    DESCRIPTOR_NAMES,
    DESCRIPTOR_UNITS,
    TRAIN_MAX,
    TRAIN_MIN,
    as_descriptor,
    support_flags,
)

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10 needs the tomli backport
    import tomli as tomllib  # type: ignore[no-redef]

LEGS: tuple[str, ...] = ("FL", "FR", "RL", "RR")
"""Leg names in model order: front-left, front-right, rear-left, rear-right."""

JOINTS: tuple[str, ...] = ("hip", "thigh", "calf")
"""Joints of one leg, proximal to distal (abduction, hip flexion, knee)."""

LINKS: tuple[str, ...] = ("hip", "thigh", "calf", "foot")
"""Links of one leg; each is a body in the generated model."""

#: Mirror signs (sx, sy, sz) applied to front-left vectors to get each leg.
LEG_SIGNS: dict[str, np.ndarray] = {
    "FL": np.array([1.0, 1.0, 1.0]),
    "FR": np.array([1.0, -1.0, 1.0]),
    "RL": np.array([-1.0, 1.0, 1.0]),
    "RR": np.array([-1.0, -1.0, 1.0]),
}

TEMPLATE_NAME = "go2"
"""The training template (docs/robots.md)."""

SCHEMA_VERSION = 1
"""Version of the robot TOML schema this module reads."""

ROBOTS_DIR_ENV = "MORFIC_ROBOTS_DIR"
"""Environment variable that overrides where robot TOMLs are read from."""

CALF_ROTOR_PLACES: tuple[str, ...] = ("thigh_joint", "calf_joint")
"""Where the calf (knee) rotor sits on the thigh link: at the hip (Unitree, Mini Cheetah) or at the
knee (ANYmal-C's KFE drive)."""

# Units, one spelling each. Every fact is checked against the unit its field expects.
U_LEN, U_MASS, U_INERTIA, U_ANGLE = "m", "kg", "kg*m^2", "rad"
U_TORQUE, U_SPEED, U_KP, U_KD = "N*m", "rad/s", "N*m/rad", "N*m*s/rad"

_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_SIDE_KEYS = (("front", "rear"), ("left", "right"))


# --------------------------------------------------------------------------------------------------
# Data classes
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Fact:
    """One fact as written in the TOML, kept for display and provenance.

    Attributes:
        key: Dotted field path, e.g. ``"links.hip.mass"``.
        value: The value as written (a number, a list, or a ``{front, rear}`` / ``{left, right}`` dict).
        unit: Unit string, e.g. ``"kg"``.
        source: Where the value comes from (repository, path, commit) or why it was chosen.
    """

    key: str
    value: Any
    unit: str
    source: str


@dataclass(frozen=True)
class Conflict:
    """A disagreement between the paper's descriptor and a public source (docs/robots.md lists them).

    Attributes:
        field: The descriptor dimension or fact concerned.
        paper: The paper's value.
        public: The public source's value.
        source: The public source.
        note: What the disagreement means and what this library chose.
    """

    field: str
    paper: Any
    public: Any
    source: str
    note: str


@dataclass(frozen=True)
class LinkInertial:
    """Mass properties of one leg link, resolved for all four legs.

    Attributes:
        mass: Bare link mass in kg (rotors and drives are separate bodies).
        com: Centre of mass in the link frame per leg, m. Shape: (4, 3), :data:`LEGS` order.
        inertia: Full inertia about the COM per leg, (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) in kg*m^2.
            Shape: (4, 6).
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True, eq=False)
class RobotSpec:
    """A validated robot: facts with units (SI) in the library's joint convention.

    Per-leg arrays are in :data:`LEGS` order (FL, FR, RL, RR) and already mirrored; per-joint
    arrays are in :data:`JOINTS` order (hip, thigh, calf).
    """

    name: str
    """Robot id, the TOML file stem (e.g. ``"go1"``)."""
    display_name: str
    """Human name (e.g. ``"Unitree Go1"``)."""
    is_template: bool
    """True only for the training template (Go2)."""
    source_path: Path
    """The TOML file this spec was read from."""
    descriptor: np.ndarray
    """The paper's 11-D descriptor in DESCRIPTOR_NAMES order (kg, rad). Shape: (11,)."""
    descriptor_source: str
    """Where the descriptor values come from (the paper's table)."""
    base_size: np.ndarray
    """Full extents of the trunk box (x, y, z), m. Shape: (3,)."""
    base_mass: float
    """Trunk mass, kg (without the hip rotors, which are separate bodies)."""
    base_com: np.ndarray
    """Trunk centre of mass in the base frame, m. Shape: (3,)."""
    base_inertia: np.ndarray
    """Trunk principal inertia about the COM (ixx, iyy, izz), kg*m^2. Shape: (3,)."""
    hip_pos: np.ndarray
    """Hip (abduction) joint position in the base frame per leg, m. Shape: (4, 3)."""
    thigh_offset: np.ndarray
    """Thigh joint position in the hip-link frame per leg, m. Shape: (4, 3)."""
    calf_offset: np.ndarray
    """Calf (knee) joint position in the thigh-link frame per leg, m. Shape: (4, 3)."""
    foot_offset: np.ndarray
    """Foot-sphere centre in the calf-link frame per leg, m. Shape: (4, 3)."""
    foot_radius: float
    """Foot sphere radius, m."""
    link_radius: np.ndarray
    """Capsule radius of the hip, thigh and calf links (a modelling choice), m. Shape: (3,)."""
    links: Mapping[str, LinkInertial]
    """Mass properties of ``hip``, ``thigh``, ``calf``, ``foot`` (bare link masses)."""
    rotor_mass: np.ndarray
    """Rotor/drive masses per leg (hip rotor -> base, thigh rotor -> hip, calf rotor -> thigh), kg.
    Zero means no rotor body. Shape: (3,)."""
    rotor_radius: float
    """Radius of the solid sphere used for a rotor's inertia (a modelling choice), m."""
    calf_rotor_at: str
    """Where the calf rotor sits on the thigh: ``"thigh_joint"`` or ``"calf_joint"``."""
    joint_range: np.ndarray
    """Joint limits per leg and joint, (min, max) rad. Shape: (4, 3, 2)."""
    torque_limit: np.ndarray
    """Peak joint torque per joint, N*m. Shape: (3,)."""
    velocity_limit: np.ndarray
    """Joint speed limit per joint, rad/s. Shape: (3,)."""
    armature: np.ndarray
    """Reflected rotor inertia per joint, kg*m^2 (0 where no public value). Shape: (3,)."""
    damping: np.ndarray
    """Passive joint damping per joint, N*m*s/rad. Shape: (3,)."""
    kp: float
    """PD stiffness of the position actuators, N*m/rad."""
    kd: float
    """PD damping of the position actuators, N*m*s/rad."""
    default_pose: np.ndarray
    """Default standing joint angles per leg and joint, rad. Shape: (4, 3)."""
    init_height: float
    """Base height at reset (keyframe ``home``), m."""
    public_total_mass: float
    """The public total mass of the robot, kg (a cross-check of the masses above)."""
    conflicts: tuple[Conflict, ...] = ()
    """Disagreements between the paper's descriptor and public sources."""
    facts: tuple[Fact, ...] = field(default=(), repr=False)
    """Every fact as written, with unit and source, in file order."""

    @property
    def link_mass(self) -> np.ndarray:
        """Bare link masses (hip, thigh, calf, foot), kg. Shape: (4,)."""
        return np.array([self.links[k].mass for k in LINKS])

    @property
    def leg_mass(self) -> float:
        """Mass of one leg including its three rotors, kg."""
        return float(self.link_mass.sum() + self.rotor_mass.sum())

    @property
    def total_mass(self) -> float:
        """Sum of every mass in the spec: base + 4 x (links + rotors), kg."""
        return float(self.base_mass + len(LEGS) * self.leg_mass)

    @property
    def default_qpos(self) -> np.ndarray:
        """Default joint angles flattened leg-major (FL hip, FL thigh, FL calf, FR hip, ...). Shape: (12,)."""
        return self.default_pose.reshape(-1).copy()

    @property
    def ctrl_range(self) -> np.ndarray:
        """Joint ranges flattened like :attr:`default_qpos`. Shape: (12, 2)."""
        return self.joint_range.reshape(-1, 2).copy()

    def support_flags(self) -> np.ndarray:
        """Out-of-support marks of the descriptor: +1 above, -1 below, 0 inside. Shape: (11,)."""
        return support_flags(self.descriptor)


# --------------------------------------------------------------------------------------------------
# Finding robots
# --------------------------------------------------------------------------------------------------


def robots_dir() -> Path:
    """Directory holding the robot TOMLs.

    Order: ``$MORFIC_ROBOTS_DIR`` if set; else ``morfic_cli/robots/`` inside an installed wheel;
    else the checkout's top-level ``robots/`` next to the package (editable install).

    Returns:
        The directory.

    Raises:
        RobotSpecError: ``MORFIC_ROBOTS_DIR`` is set but is not a directory, or none is found.
    """
    env = os.environ.get(ROBOTS_DIR_ENV, "")
    if env:
        path = Path(env).expanduser()
        if not path.is_dir():
            raise RobotSpecError(
                f"{ROBOTS_DIR_ENV}={env} is not a directory; point it at a folder of robot TOMLs or unset it."
            )
        return path
    packaged = resources.files("morfic_cli") / "robots"
    if packaged.is_dir():
        return Path(str(packaged))
    checkout = Path(__file__).resolve().parents[2] / "robots"
    if checkout.is_dir():
        return checkout
    raise RobotSpecError(
        f"no robot library found (looked in {packaged} and {checkout}); reinstall morfic or set {ROBOTS_DIR_ENV}."
    )


def list_robots() -> list[str]:
    """Names of the robots in :func:`robots_dir`: the template (go2) first, the rest sorted."""
    names = sorted(p.stem for p in robots_dir().glob("*.toml"))
    return sorted(names, key=lambda n: (n != TEMPLATE_NAME, n))


def load_robot(name: str) -> RobotSpec:
    """Load a robot of the library by name.

    Args:
        name: Robot id, e.g. ``"go1"`` (see :func:`list_robots`).

    Returns:
        The validated spec.

    Raises:
        UnknownNameError: no such robot.
        RobotSpecError: the TOML is malformed or physically impossible.
    """
    names = list_robots()
    if name not in names:
        raise UnknownNameError("robot", name, names)
    spec = load_robot_file(robots_dir() / f"{name}.toml")
    if spec.name != name:
        raise RobotSpecError(
            f"{spec.source_path}: name: '{spec.name}' does not match the file name '{name}.toml'; "
            "rename the file or fix the name."
        )
    return spec


def load_robot_file(path: str | os.PathLike[str]) -> RobotSpec:
    """Load and validate one robot TOML file.

    Args:
        path: The file.

    Returns:
        The validated spec.

    Raises:
        RobotSpecError: unreadable file, TOML syntax error, missing or unknown key, wrong unit,
            impossible value (negative mass or length, min limit above max, non-finite number,
            default pose outside the limits) or a bad descriptor. The message names the file and
            the field and says what to fix.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise RobotSpecError(f"{path}: cannot read the robot file ({exc.strerror}).") from exc
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise RobotSpecError(f"{path}: not UTF-8 text; save the robot TOML as UTF-8.") from exc
    except tomllib.TOMLDecodeError as exc:
        raise RobotSpecError(f"{path}: TOML syntax error: {exc}; fix the syntax (https://toml.io).") from exc
    return _parse(data, _Reader(path))


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------


class _Reader:
    """Strict reading of nested tables: every key must be known, every fact well-formed."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.facts: list[Fact] = []

    def fail(self, where: str, problem: str) -> RobotSpecError:
        return RobotSpecError(f"{self.path}: field '{where}': {problem}")

    def table(self, data: Mapping[str, Any], key: str, where: str = "") -> dict[str, Any]:
        full = f"{where}.{key}" if where else key
        if key not in data:
            raise self.fail(full, f"missing table [{full}]; add it (see docs/robots.md).")
        value = data[key]
        if not isinstance(value, dict):
            raise self.fail(full, f"expected a table, got {type(value).__name__}.")
        return value

    def require(self, data: Mapping[str, Any], key: str, where: str) -> Any:
        if key not in data:
            full = f"{where}.{key}" if where else key
            raise self.fail(full, "missing; add it (see docs/robots.md).")
        return data[key]

    def no_unknown(self, data: Mapping[str, Any], known: tuple[str, ...], where: str) -> None:
        unknown = [k for k in data if k not in known]
        if unknown:
            full = f"{where}.{unknown[0]}" if where else unknown[0]
            raise self.fail(
                full, f"unknown key '{unknown[0]}' in [{where or 'top level'}]; known keys are: {', '.join(known)}."
            )

    def string(self, data: Mapping[str, Any], key: str, where: str) -> str:
        value = self.require(data, key, where)
        if not isinstance(value, str) or not value.strip():
            raise self.fail(f"{where}.{key}" if where else key, f"expected a non-empty string, got {value!r}.")
        return value

    def number(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(where, f"expected a number, got {value!r}.")
        if not math.isfinite(value):
            raise self.fail(where, f"must be finite, got {value!r}; write a finite number.")
        return float(value)

    def numbers(self, value: Any, shape: tuple[int, ...], where: str) -> np.ndarray:
        if shape == ():
            return np.array(self.number(value, where))
        if not isinstance(value, list) or len(value) != shape[0]:
            raise self.fail(where, f"expected a list of {shape[0]} numbers, got {value!r}.")
        return np.array([self.number(v, f"{where}[{i}]") for i, v in enumerate(value)])

    def quantity(
        self,
        data: Mapping[str, Any],
        key: str,
        where: str,
        unit: str,
        shape: tuple[int, ...] = (),
        per_leg: bool = False,
    ) -> np.ndarray:
        """Read ``{ value|front,rear|left,right, unit, source }``; per-leg values come back (4, *shape)."""
        full = f"{where}.{key}" if where else key
        fact = self.require(data, key, where)
        if not isinstance(fact, dict):
            raise self.fail(
                full, f'expected an inline table {{ value = ..., unit = "{unit}", source = "..." }}, got {fact!r}.'
            )
        sides = next((pair for pair in _SIDE_KEYS if pair[0] in fact or pair[1] in fact), None)
        value_keys: tuple[str, ...] = sides if (per_leg and sides) else ("value",)
        self.no_unknown(fact, (*value_keys, "unit", "source", "note"), full)
        got_unit = self.require(fact, "unit", full)
        if got_unit != unit:
            raise self.fail(
                full,
                f"wrong unit '{got_unit}'; this field is in '{unit}' (convert the value and write unit = \"{unit}\").",
            )
        source = self.string(fact, "source", full)
        if value_keys == ("value",):
            arr = self.numbers(self.require(fact, "value", full), shape, f"{full}.value")
            out = np.broadcast_to(arr, (len(LEGS), *shape)).copy() if per_leg else arr
            raw: Any = fact["value"]
        else:
            a, b = (self.numbers(self.require(fact, k, full), shape, f"{full}.{k}") for k in value_keys)
            out = np.stack([_side_pick(leg, value_keys, a, b) for leg in LEGS])
            raw = {k: fact[k] for k in value_keys}
        self.facts.append(Fact(full, raw, unit, source))
        return out


def _side_pick(leg: str, keys: tuple[str, ...], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if keys == ("front", "rear"):
        return a if leg[0] == "F" else b
    return a if leg[1] == "L" else b


def _mirror(v_fl: np.ndarray) -> np.ndarray:
    """Mirror a front-left vector to all legs. Shape: (3,) -> (4, 3)."""
    return np.stack([v_fl * LEG_SIGNS[leg] for leg in LEGS])


def _positive(r: _Reader, arr: np.ndarray, where: str, what: str, allow_zero: bool = False) -> None:
    bad = arr < 0 if allow_zero else arr <= 0
    if np.any(bad):
        bound = ">= 0" if allow_zero else "> 0"
        raise r.fail(
            where,
            f"{what} must be {bound}, got {np.asarray(arr).tolist()}; a physical {what} cannot be "
            f"{'negative' if allow_zero else 'zero or negative'}.",
        )


_TOP_KEYS = (
    "schema_version",
    "name",
    "display_name",
    "template",
    "public_total_mass",
    "descriptor_source",
    "notes",
    "base",
    "leg",
    "links",
    "rotors",
    "joint_limits",
    "actuators",
    "default_pose",
    "descriptor",
    "conflicts",
)


def _parse(data: dict[str, Any], r: _Reader) -> RobotSpec:
    r.no_unknown(data, _TOP_KEYS, "")
    version = r.require(data, "schema_version", "")
    if version != SCHEMA_VERSION:
        raise r.fail("schema_version", f"this morfic reads schema_version = {SCHEMA_VERSION}, got {version!r}.")
    name = r.string(data, "name", "")
    if not _NAME_RE.match(name):
        raise r.fail("name", f"'{name}' must be lower-case letters, digits and '_' (it is the robot id).")
    template = r.require(data, "template", "")
    if not isinstance(template, bool):
        raise r.fail("template", f"expected true or false, got {template!r}.")
    if "notes" in data and not isinstance(data["notes"], str):
        raise r.fail("notes", "expected a string.")
    total = r.quantity(data, "public_total_mass", "", U_MASS)
    _positive(r, total, "public_total_mass", "mass")
    base = _parse_base(data, r)
    leg = _parse_leg(data, r)
    links = _parse_links(data, r, leg)
    rotors = _parse_rotors(data, r)
    joint_range = _parse_limits(data, r)
    act = _parse_actuators(data, r)
    pose, init_height = _parse_pose(data, r, joint_range)
    descriptor = _parse_descriptor(data, r)
    return RobotSpec(
        name=name,
        display_name=r.string(data, "display_name", ""),
        is_template=template,
        source_path=r.path,
        descriptor=descriptor,
        descriptor_source=r.string(data, "descriptor_source", ""),
        base_size=base["size"],
        base_mass=float(base["mass"]),
        base_com=base["com"],
        base_inertia=base["inertia"],
        hip_pos=leg["hip_pos"],
        thigh_offset=leg["thigh_offset"],
        calf_offset=leg["calf_offset"],
        foot_offset=leg["foot_offset"],
        foot_radius=float(leg["foot_radius"]),
        link_radius=leg["link_radius"],
        links=links,
        rotor_mass=rotors["mass"],
        rotor_radius=float(rotors["radius"]),
        calf_rotor_at=rotors["calf_at"],
        joint_range=joint_range,
        torque_limit=act["torque_limit"],
        velocity_limit=act["velocity_limit"],
        armature=act["armature"],
        damping=act["damping"],
        kp=float(act["kp"]),
        kd=float(act["kd"]),
        default_pose=pose,
        init_height=init_height,
        public_total_mass=float(total),
        conflicts=_parse_conflicts(data, r),
        facts=tuple(r.facts),
    )


def _parse_base(data: Mapping[str, Any], r: _Reader) -> dict[str, Any]:
    t = r.table(data, "base")
    r.no_unknown(t, ("size", "mass", "com", "inertia"), "base")
    out = {
        "size": r.quantity(t, "size", "base", U_LEN, (3,)),
        "mass": r.quantity(t, "mass", "base", U_MASS),
        "com": r.quantity(t, "com", "base", U_LEN, (3,)),
        "inertia": r.quantity(t, "inertia", "base", U_INERTIA, (3,)),
    }
    _positive(r, out["size"], "base.size", "length")
    _positive(r, out["mass"], "base.mass", "mass")
    _check_inertia(r, out["inertia"], "base.inertia")
    return out


def _check_inertia(r: _Reader, diag: np.ndarray, where: str) -> None:
    _positive(r, diag, where, "moment of inertia")
    a, b, c = diag
    if a + b < c or b + c < a or a + c < b:
        raise r.fail(
            where,
            f"{diag.tolist()} breaks the triangle inequality (each moment must be at most the sum "
            "of the other two); check for a typo such as a misplaced decimal point.",
        )


def _parse_leg(data: Mapping[str, Any], r: _Reader) -> dict[str, Any]:
    t = r.table(data, "leg")
    keys = ("hip_pos", "thigh_offset", "calf_offset", "foot_offset", "foot_radius", "link_radius")
    r.no_unknown(t, keys, "leg")
    fl = {k: r.quantity(t, k, "leg", U_LEN, (3,)) for k in keys[:4]}
    radius = r.quantity(t, "foot_radius", "leg", U_LEN)
    link_radius = r.quantity(t, "link_radius", "leg", U_LEN, (3,))
    if fl["hip_pos"][0] <= 0 or fl["hip_pos"][1] <= 0:
        raise r.fail(
            "leg.hip_pos",
            f"{fl['hip_pos'].tolist()}: give the front-left hip, with x > 0 and y > 0; "
            "the other legs are mirrored from it.",
        )
    for k in ("calf_offset", "foot_offset"):
        if np.linalg.norm(fl[k]) <= 0:
            raise r.fail(f"leg.{k}", "a link length must be > 0, got a zero offset.")
    _positive(r, radius, "leg.foot_radius", "length")
    _positive(r, link_radius, "leg.link_radius", "length")
    if link_radius[2] > radius:
        raise r.fail(
            "leg.link_radius",
            f"calf capsule radius {link_radius[2]:g} m is larger than the foot radius "
            f"{float(radius):g} m; the foot must touch the ground first.",
        )
    out: dict[str, Any] = {k: _mirror(v) for k, v in fl.items()}
    out["foot_radius"] = radius
    out["link_radius"] = link_radius
    return out


def _cylinder_inertia(mass: float, radius: float, seg: np.ndarray) -> np.ndarray:
    """Full inertia of a solid cylinder along ``seg`` about its centre, (Ixx, Iyy, Izz, Ixy, Ixz, Iyz).

    I = m r^2 / 2 * u u^T + m (3 r^2 + L^2) / 12 * (E - u u^T), u = seg / L.
    """
    length = float(np.linalg.norm(seg))
    u = seg / length
    uu = np.outer(u, u)
    mat = mass * radius**2 / 2 * uu + mass * (3 * radius**2 + length**2) / 12 * (np.eye(3) - uu)
    return np.array([mat[0, 0], mat[1, 1], mat[2, 2], mat[0, 1], mat[0, 2], mat[1, 2]])


def _parse_links(data: Mapping[str, Any], r: _Reader, leg: Mapping[str, Any]) -> dict[str, LinkInertial]:
    t = r.table(data, "links")
    r.no_unknown(t, LINKS, "links")
    segments = {"hip": leg["thigh_offset"], "thigh": leg["calf_offset"], "calf": leg["foot_offset"]}
    out: dict[str, LinkInertial] = {}
    for i, link in enumerate(LINKS):
        where = f"links.{link}"
        lt = r.table(t, link, "links")
        r.no_unknown(lt, ("mass", "com", "inertia"), where)
        mass = float(r.quantity(lt, "mass", where, U_MASS))
        _positive(r, np.array(mass), f"{where}.mass", "mass", allow_zero=link == "foot")
        if link == "foot":
            com = np.zeros((4, 3))
        elif "com" in lt:
            com = _mirror(r.quantity(lt, "com", where, U_LEN, (3,)))
        else:  # documented default: the middle of the link's segment
            com = segments[link] / 2
        if "inertia" in lt:
            diag = r.quantity(lt, "inertia", where, U_INERTIA, (3,))
            _check_inertia(r, diag, f"{where}.inertia")
            inertia = np.tile(np.concatenate([diag, np.zeros(3)]), (4, 1))
        elif link == "foot":  # solid sphere of the foot radius
            moment = 0.4 * mass * float(leg["foot_radius"]) ** 2
            inertia = np.tile([moment, moment, moment, 0.0, 0.0, 0.0], (4, 1))
        else:  # solid cylinder of the capsule radius along the link's segment
            inertia = np.stack([_cylinder_inertia(mass, float(leg["link_radius"][i]), seg) for seg in segments[link]])
        out[link] = LinkInertial(mass=mass, com=com, inertia=inertia)
    return out


def _parse_rotors(data: Mapping[str, Any], r: _Reader) -> dict[str, Any]:
    t = r.table(data, "rotors")
    r.no_unknown(t, ("hip", "thigh", "calf", "calf_at", "radius"), "rotors")
    mass = np.array([float(r.quantity(t, j, "rotors", U_MASS)) for j in JOINTS])
    for j, m in zip(JOINTS, mass, strict=True):
        _positive(r, np.array(m), f"rotors.{j}", "mass", allow_zero=True)
    radius = r.quantity(t, "radius", "rotors", U_LEN)
    _positive(r, radius, "rotors.radius", "length")
    calf_at = r.string(t, "calf_at", "rotors")
    if calf_at not in CALF_ROTOR_PLACES:
        raise r.fail("rotors.calf_at", f"'{calf_at}' is not one of {', '.join(CALF_ROTOR_PLACES)}.")
    return {"mass": mass, "radius": radius, "calf_at": calf_at}


def _parse_limits(data: Mapping[str, Any], r: _Reader) -> np.ndarray:
    t = r.table(data, "joint_limits")
    r.no_unknown(t, JOINTS, "joint_limits")
    ranges = np.stack([r.quantity(t, j, "joint_limits", U_ANGLE, (2,), per_leg=True) for j in JOINTS], axis=1)
    for li, leg in enumerate(LEGS):
        for ji, joint in enumerate(JOINTS):
            lo, hi = ranges[li, ji]
            if lo >= hi:
                raise r.fail(
                    f"joint_limits.{joint}",
                    f"{leg} min limit {lo:g} rad is not below the max limit "
                    f"{hi:g} rad; write [min, max] with min < max.",
                )
    return ranges


def _parse_actuators(data: Mapping[str, Any], r: _Reader) -> dict[str, Any]:
    t = r.table(data, "actuators")
    per_joint = {"torque_limit": U_TORQUE, "velocity_limit": U_SPEED, "armature": U_INERTIA, "damping": U_KD}
    r.no_unknown(t, (*per_joint, "kp", "kd"), "actuators")
    out: dict[str, Any] = {k: r.quantity(t, k, "actuators", u, (3,)) for k, u in per_joint.items()}
    out["kp"] = r.quantity(t, "kp", "actuators", U_KP)
    out["kd"] = r.quantity(t, "kd", "actuators", U_KD)
    _positive(r, out["torque_limit"], "actuators.torque_limit", "torque limit")
    _positive(r, out["velocity_limit"], "actuators.velocity_limit", "velocity limit")
    _positive(r, out["armature"], "actuators.armature", "armature", allow_zero=True)
    _positive(r, out["damping"], "actuators.damping", "damping", allow_zero=True)
    _positive(r, out["kp"], "actuators.kp", "stiffness")
    _positive(r, out["kd"], "actuators.kd", "damping", allow_zero=True)
    return out


def _parse_pose(data: Mapping[str, Any], r: _Reader, joint_range: np.ndarray) -> tuple[np.ndarray, float]:
    t = r.table(data, "default_pose")
    r.no_unknown(t, (*JOINTS, "init_height"), "default_pose")
    pose = np.stack([r.quantity(t, j, "default_pose", U_ANGLE, per_leg=True) for j in JOINTS], axis=1)
    for li, leg in enumerate(LEGS):
        for ji, joint in enumerate(JOINTS):
            lo, hi = joint_range[li, ji]
            if not lo <= pose[li, ji] <= hi:
                raise r.fail(
                    f"default_pose.{joint}",
                    f"{leg} default {pose[li, ji]:g} rad is outside the joint "
                    f"limits [{lo:g}, {hi:g}] rad; fix the pose or the limits.",
                )
    height = r.quantity(t, "init_height", "default_pose", U_LEN)
    _positive(r, height, "default_pose.init_height", "length")
    return pose, float(height)


def _parse_descriptor(data: Mapping[str, Any], r: _Reader) -> np.ndarray:
    t = r.table(data, "descriptor")
    r.no_unknown(t, DESCRIPTOR_NAMES, "descriptor")
    for key in DESCRIPTOR_NAMES:
        r.number(r.require(t, key, "descriptor"), f"descriptor.{key}")
    try:
        return as_descriptor(t, what=f"{r.path}: [descriptor]")
    except DescriptorError as exc:
        raise RobotSpecError(
            f"{exc} Fix field 'descriptor' (keys {', '.join(DESCRIPTOR_NAMES)}, in kg and rad)."
        ) from exc


def _parse_conflicts(data: Mapping[str, Any], r: _Reader) -> tuple[Conflict, ...]:
    items = data.get("conflicts", [])
    if not isinstance(items, list):
        raise r.fail("conflicts", "expected an array of tables [[conflicts]].")
    out = []
    keys = ("field", "paper", "public", "source", "note")
    for i, item in enumerate(items):
        where = f"conflicts[{i}]"
        if not isinstance(item, dict):
            raise r.fail(where, "expected a table with keys field, paper, public, source, note.")
        r.no_unknown(item, keys, where)
        out.append(
            Conflict(
                field=r.string(item, "field", where),
                paper=r.require(item, "paper", where),
                public=r.require(item, "public", where),
                source=r.string(item, "source", where),
                note=r.string(item, "note", where),
            )
        )
    return tuple(out)


# --------------------------------------------------------------------------------------------------
# Rows for display (used by `morfic robots show`)
# --------------------------------------------------------------------------------------------------

SUPPORT_MARKS = {1: "↑", -1: "↓", 0: ""}
"""Paper-style marks for a descriptor value above / below the training support."""


def descriptor_rows(spec: RobotSpec) -> list[dict[str, Any]]:
    """The descriptor as rows with the training support and the paper's up/down marks.

    Args:
        spec: The robot.

    Returns:
        One dict per dimension: ``name``, ``unit``, ``value``, ``train_min``, ``train_max``,
        ``support`` (+1 above, -1 below, 0 inside) and ``mark`` (↑, ↓ or empty).
    """
    flags = spec.support_flags()
    return [
        {
            "name": n,
            "unit": u,
            "value": float(v),
            "train_min": float(lo),
            "train_max": float(hi),
            "support": int(f),
            "mark": SUPPORT_MARKS[int(f)],
        }
        for n, u, v, lo, hi, f in zip(
            DESCRIPTOR_NAMES, DESCRIPTOR_UNITS, spec.descriptor, TRAIN_MIN, TRAIN_MAX, flags, strict=True
        )
    ]


def _format_value(value: Any) -> str:
    if isinstance(value, dict):
        return ", ".join(f"{k} {_format_value(v)}" for k, v in value.items())
    if isinstance(value, list):
        return "[" + ", ".join(_format_value(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def fact_rows(spec: RobotSpec, raw: bool = False) -> list[dict[str, Any]]:
    """Every fact of the spec as a row: ``field``, ``value``, ``unit``, ``source``.

    ``value`` is text as written (``[0.3762, 0.0935, 0.114]``), or with ``raw`` the TOML value itself (numbers as
    numbers, lists as lists: the JSON output).
    """
    fmt = (lambda v: v) if raw else _format_value
    return [{"field": f.key, "value": fmt(f.value), "unit": f.unit, "source": f.source} for f in spec.facts]


def conflict_rows(spec: RobotSpec, raw: bool = False) -> list[dict[str, Any]]:
    """The spec's conflicts with public sources as rows (field, paper, public, source, note); ``raw`` as above."""
    fmt = (lambda v: v) if raw else _format_value
    return [
        {"field": c.field, "paper": fmt(c.paper), "public": fmt(c.public), "source": c.source, "note": c.note}
        for c in spec.conflicts
    ]


def iter_robots() -> Iterator[RobotSpec]:
    """Load every robot of the library, in :func:`list_robots` order."""
    for name in list_robots():
        yield load_robot(name)
