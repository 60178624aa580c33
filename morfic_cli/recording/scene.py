"""The 3D scene of a rollout for Foxglove's 3D panel: MuJoCo geoms as primitives, bodies as frames.

Frame tree (one per scene env ``i``, laid out side by side along world y so envs never overlap)::

    world -> env{i}/world (translation (0, i * ENV_SPACING_M, 0), fixed)
          -> env{i}/base (the free joint: MuJoCo's xpos / xquat of the base)
          -> env{i}/FL_hip -> env{i}/FL_thigh -> env{i}/FL_calf -> env{i}/FL_foot ...

Every transform is parent-relative (the parent's frame is the parent body's MuJoCo frame, ``env{i}/world`` for the
bodies of the world body): for a body b with parent p, translation = R(q_p)^T (x_b - x_p) and rotation =
conj(q_p) q_b, with x / q MuJoCo's ``xpos`` / ``xquat`` after ``mj_kinematics``. Bodies without a joint (feet,
rotors) and the ``env{i}/world`` offsets are fixed: :meth:`RolloutScene.static_transforms` gives them once;
:meth:`RolloutScene.step_transforms` gives the moving bodies (those with joints) each policy step.

:meth:`RolloutScene.scene_update` is one ``foxglove.SceneUpdate``: an entity per geom, in its body's frame
(``frame_locked``, so it moves with the body), with the geom's pose in the body (``geom_pos`` / ``geom_quat``) and
colour (``geom_rgba``); entity metadata ``geom``, ``type`` and ``size`` (MuJoCo's ``geom_size``) name what it
draws. Primitives: box -> cube of size 2 * half-sizes; sphere -> sphere of diameter 2r; ellipsoid -> sphere scaled
2 * radii; cylinder -> cylinder (diameter 2r, height 2 * half-length); capsule -> that cylinder plus two spheres of
diameter 2r at z = +-half-length of the geom frame; plane (the floor) -> a thin cube :data:`FLOOR_SIZE_M` in frame
``world`` with its top at z = 0. Other geom types (meshes, height fields) are not drawn (our robots have none).
Quaternions here are (w, x, y, z) as MuJoCo's; Foxglove's ``Quaternion`` message names the same components.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.CylinderPrimitive_pb2 import CylinderPrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp

from morfic_cli.quaternion import quat_conj_mul, quat_rotate_inverse

ROOT_FRAME = "world"
"""The frame every env's tree hangs from (Foxglove's display frame)."""

ENV_SPACING_M = 1.5
"""Distance between neighbouring envs along world y, m (wider than the largest robot, B1)."""

FLOOR_SIZE_M = (200.0, 200.0, 0.01)
"""Size of the drawn floor (x, y, thickness), m: 200 m covers a 100 s walk at 2 m/s."""

FLOOR_ORIGIN_X_M = 90.0
"""Floor centre along x, m: it starts 10 m behind the start line."""

GEOM_TYPES = {
    mujoco.mjtGeom.mjGEOM_PLANE: "plane",
    mujoco.mjtGeom.mjGEOM_SPHERE: "sphere",
    mujoco.mjtGeom.mjGEOM_CAPSULE: "capsule",
    mujoco.mjtGeom.mjGEOM_ELLIPSOID: "ellipsoid",
    mujoco.mjtGeom.mjGEOM_CYLINDER: "cylinder",
    mujoco.mjtGeom.mjGEOM_BOX: "box",
}
"""MuJoCo geom types drawn, by the name used in entity metadata."""


def env_frame(env: int, body: str) -> str:
    """Frame id of a body of env ``env``, e.g. ``env3/FL_calf``; body ``world`` is that env's origin."""
    return f"env{env}/{body}"


def timestamp(ns: int) -> Timestamp:
    """A protobuf Timestamp of ``ns`` nanoseconds."""
    return Timestamp(seconds=ns // 1_000_000_000, nanos=ns % 1_000_000_000)


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int, prefix: str) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"{prefix}{i}"


class RolloutScene:
    """The scene of some envs of a rollout: geoms once, body frames from each step's qpos.

    Args:
        models: The MjModel of each scene env (all with the same body tree, e.g. the first envs of a rollout).
        env_ids: The env index of each model in the rollout (frame names ``env{i}/...`` and the layout use it).
        qpos_adr: qpos addresses of the 12 joints in ``joint_pos`` order (the free joint is qpos[0:7]).
            Shape: (12,).
    """

    def __init__(
        self, models: Sequence[mujoco.MjModel], env_ids: Sequence[int], qpos_adr: Sequence[int] | np.ndarray
    ) -> None:
        if len(models) != len(env_ids) or not models:
            raise ValueError(f"need one model per scene env, got {len(models)} models for env ids {list(env_ids)}")
        self.models = list(models)
        self.env_ids = [int(i) for i in env_ids]
        self.qpos_adr = np.asarray(qpos_adr, dtype=np.int64)
        m = self.models[0]
        self.body_names = [_name(m, mujoco.mjtObj.mjOBJ_BODY, b, "body") for b in range(m.nbody)]
        self.parent = np.asarray(m.body_parentid)
        self.moving = np.flatnonzero(np.asarray(m.body_jntnum) > 0)  # bodies with a joint, parent-relative pose
        self.fixed = np.array([b for b in range(1, m.nbody) if m.body_jntnum[b] == 0], dtype=np.int64)
        self._data = [mujoco.MjData(model) for model in self.models]
        self._names: dict[tuple[int, ...], list[list[tuple[str, str]]]] = {}

    @property
    def num_envs(self) -> int:
        """E, the number of scene envs."""
        return len(self.models)

    def offset(self, env: int) -> np.ndarray:
        """Translation of ``env{env}/world`` in ``world``: envs side by side along y. Shape: (3,)."""
        return np.array([0.0, env * ENV_SPACING_M, 0.0])

    def qpos(self, base_pos: np.ndarray, base_quat: np.ndarray, joint_pos: np.ndarray) -> np.ndarray:
        """The scene envs' qpos from a step's recorded arrays of all N envs (rows ``env_ids``).

        Args:
            base_pos: Shape: (N, 3).
            base_quat: (w, x, y, z). Shape: (N, 4).
            joint_pos: Shape: (N, 12).

        Returns:
            float64 qpos. Shape: (E, nq).
        """
        ids = self.env_ids
        out = np.zeros((len(ids), self.models[0].nq))
        out[:, 0:3] = base_pos[ids]
        out[:, 3:7] = base_quat[ids]
        out[:, self.qpos_adr] = joint_pos[ids]
        return out

    def body_poses(self, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """MuJoCo's ``xpos`` / ``xquat`` of every body of every scene env at ``qpos`` (``mj_kinematics``).

        Args:
            qpos: Shape: (E, nq).

        Returns:
            ``(xpos (E, nbody, 3), xquat (E, nbody, 4))``.
        """
        xpos = np.empty((self.num_envs, self.models[0].nbody, 3))
        xquat = np.empty((self.num_envs, self.models[0].nbody, 4))
        for e, (model, data) in enumerate(zip(self.models, self._data, strict=True)):
            data.qpos[:] = qpos[e]
            mujoco.mj_kinematics(model, data)
            xpos[e], xquat[e] = data.xpos, data.xquat
        return xpos, xquat

    def _transforms(self, bodies: np.ndarray, xpos: np.ndarray, xquat: np.ndarray, stamp: Timestamp) -> list:
        """Parent-relative FrameTransforms of ``bodies`` of every scene env."""
        p = self.parent[bodies]
        rel_pos = quat_rotate_inverse(xquat[:, p], xpos[:, bodies] - xpos[:, p])  # (E, B, 3)
        rel_quat = quat_conj_mul(xquat[:, p], xquat[:, bodies])  # (E, B, 4)
        key = tuple(bodies.tolist())
        if key not in self._names:  # (parent, child) frame ids per env
            self._names[key] = [
                [
                    (env_frame(env, self.body_names[pk]), env_frame(env, self.body_names[b]))
                    for pk, b in zip(p.tolist(), key, strict=True)
                ]
                for env in self.env_ids
            ]
        names = self._names[key]
        out = []
        for env_names, ts, qs in zip(names, rel_pos.tolist(), rel_quat.tolist(), strict=True):
            out += [
                FrameTransform(
                    timestamp=stamp,
                    parent_frame_id=parent,
                    child_frame_id=child,
                    translation=Vector3(x=t[0], y=t[1], z=t[2]),
                    rotation=Quaternion(w=q[0], x=q[1], y=q[2], z=q[3]),
                )
                for (parent, child), t, q in zip(env_names, ts, qs, strict=True)
            ]
        return out

    def static_transforms(self, log_time_ns: int) -> FrameTransforms:
        """The fixed frames: each env's origin in ``world`` and every body without a joint in its parent."""
        stamp = timestamp(log_time_ns)
        out = [
            FrameTransform(
                timestamp=stamp,
                parent_frame_id=ROOT_FRAME,
                child_frame_id=env_frame(env, "world"),
                translation=Vector3(x=o[0], y=o[1], z=o[2]),
                rotation=Quaternion(w=1.0),
            )
            for env, o in ((env, self.offset(env)) for env in self.env_ids)
        ]
        if len(self.fixed):
            xpos, xquat = self.body_poses(np.stack([m.qpos0 for m in self.models]))
            out += self._transforms(self.fixed, xpos, xquat, stamp)
        return FrameTransforms(transforms=out)

    def step_transforms(self, qpos: np.ndarray, log_time_ns: int) -> FrameTransforms:
        """The moving bodies' parent-relative transforms at ``qpos``. Shape: qpos (E, nq)."""
        xpos, xquat = self.body_poses(qpos)
        return FrameTransforms(transforms=self._transforms(self.moving, xpos, xquat, timestamp(log_time_ns)))

    def scene_update(self, log_time_ns: int) -> SceneUpdate:
        """Every drawn geom of every scene env as an entity in its body's frame, and the floor once."""
        stamp = timestamp(log_time_ns)
        entities, floor = [], None
        for model, env in zip(self.models, self.env_ids, strict=True):
            for g in range(model.ngeom):
                kind = GEOM_TYPES.get(mujoco.mjtGeom(model.geom_type[g]))
                if kind is None:
                    continue
                name = _name(model, mujoco.mjtObj.mjOBJ_GEOM, g, "geom")
                size = np.asarray(model.geom_size[g], dtype=float)
                meta = [
                    KeyValuePair(key="geom", value=name),
                    KeyValuePair(key="type", value=kind),
                    KeyValuePair(key="size", value=" ".join(repr(float(s)) for s in size)),
                ]
                rgba = model.geom_rgba[g]
                color = Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
                if kind == "plane":
                    if floor is None:
                        floor = SceneEntity(
                            timestamp=stamp,
                            frame_id=ROOT_FRAME,
                            id="floor",
                            frame_locked=True,
                            metadata=meta,
                            cubes=[
                                CubePrimitive(
                                    pose=Pose(
                                        position=Vector3(x=FLOOR_ORIGIN_X_M, y=0.0, z=-FLOOR_SIZE_M[2] / 2),
                                        orientation=Quaternion(w=1.0),
                                    ),
                                    size=Vector3(x=FLOOR_SIZE_M[0], y=FLOOR_SIZE_M[1], z=FLOOR_SIZE_M[2]),
                                    color=color,
                                )
                            ],
                        )
                    continue
                entity = SceneEntity(
                    timestamp=stamp,
                    frame_id=env_frame(env, self.body_names[model.geom_bodyid[g]]),
                    id=env_frame(env, name),
                    frame_locked=True,
                    metadata=meta,
                )
                _add_primitives(entity, kind, model.geom_pos[g], model.geom_quat[g], size, color)
                entities.append(entity)
        return SceneUpdate(entities=([floor] if floor is not None else []) + entities)


def _pose(pos: np.ndarray, quat: np.ndarray) -> Pose:
    return Pose(
        position=Vector3(x=pos[0], y=pos[1], z=pos[2]),
        orientation=Quaternion(w=quat[0], x=quat[1], y=quat[2], z=quat[3]),
    )


def _add_primitives(
    entity: SceneEntity, kind: str, pos: np.ndarray, quat: np.ndarray, size: np.ndarray, color: Color
) -> None:
    """The Foxglove primitives of one geom (module docstring), in the geom's pose within its body."""
    pose = _pose(pos, quat)
    if kind == "box":
        entity.cubes.append(
            CubePrimitive(pose=pose, size=Vector3(x=2 * size[0], y=2 * size[1], z=2 * size[2]), color=color)
        )
    elif kind in ("sphere", "ellipsoid"):
        r = size if kind == "ellipsoid" else np.full(3, size[0])
        entity.spheres.append(SpherePrimitive(pose=pose, size=Vector3(x=2 * r[0], y=2 * r[1], z=2 * r[2]), color=color))
    else:  # cylinder or capsule: radius size[0], half-length size[1] along the geom's z
        d, h = 2 * size[0], 2 * size[1]
        entity.cylinders.append(
            CylinderPrimitive(pose=pose, size=Vector3(x=d, y=d, z=h), bottom_scale=1.0, top_scale=1.0, color=color)
        )
        if kind == "capsule":
            axis = _rotate(quat, np.array([0.0, 0.0, size[1]]))
            for sign in (1.0, -1.0):
                entity.spheres.append(
                    SpherePrimitive(pose=_pose(pos + sign * axis, quat), size=Vector3(x=d, y=d, z=d), color=color)
                )


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v for a (w, x, y, z) quaternion. Shapes: (4,), (3,) -> (3,)."""
    out = np.zeros(3)
    mujoco.mju_rotVecQuat(out, v, np.asarray(q, dtype=float))
    return out
