"""World positions, orientations and linear velocities of G1 links along a trajectory, from MuJoCo.

For each frame the robot's ``(qpos, qvel)`` goes into a robot-only MuJoCo model (the G1 of
:func:`pipeline.robot.g1_model`), forward kinematics places the bodies, and
``mj_comVel`` gives each body's 6-D velocity ``cvel = (w, v_c)`` in world orientation at the centre
of mass ``c`` of its kinematic tree; the velocity of the body origin ``x`` (where the features query
the field) is ``v = v_c + w x (x - c)``, i.e. ``J_p(q) qd`` for the origin: the link velocity of the
paper's DF features, exact for the simulated state (no finite differences).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.errors import InputError
from pipeline.robot import g1_model
from pipeline.xp import namespace


@dataclass(frozen=True)
class LinkMotion:
    """``pos (T, K, 3)`` world [m], ``rot (T, K, 3, 3)`` body-to-world rotation, ``vel (T, K, 3)`` world
    linear velocity of the body origin [m/s], for the links ``names``."""

    names: tuple[str, ...]
    pos: np.ndarray
    rot: np.ndarray
    vel: np.ndarray


def body_ids(model: mujoco.MjModel, links: tuple[str, ...] | list[str], source: str | None = None) -> list[int]:
    """MuJoCo body ids of ``links``; a name not on the robot is a one-line :class:`InputError`."""
    ids = []
    for name in links:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if i < 0:
            raise InputError(
                source,
                "links",
                f"link {name!r} is not a body of the G1 model (e.g. pelvis, torso_link, left_wrist_yaw_link)",
            )
        ids.append(i)
    return ids


def link_motion(qpos: np.ndarray, qvel: np.ndarray, links: tuple[str, ...], source: str | None = None) -> LinkMotion:
    """Link poses and velocities for G1 ``qpos (T, 36)`` and MuJoCo ``qvel (T, 35)`` (root linear velocity
    in the world, root angular velocity in the root frame, joint velocities)."""
    m = g1_model()
    ids = body_ids(m, links, source)
    if qpos.shape[1:] != (m.nq,) or qvel.shape[1:] != (m.nv,) or len(qpos) != len(qvel):
        raise InputError(
            source, "qpos/qvel", f"expected (T, {m.nq}) and (T, {m.nv}), got {qpos.shape} and {qvel.shape}"
        )
    d = mujoco.MjData(m)
    T, K = len(qpos), len(ids)
    pos, rot, vel = np.zeros((T, K, 3)), np.zeros((T, K, 3, 3)), np.zeros((T, K, 3))
    for t in range(T):
        d.qpos[:], d.qvel[:] = qpos[t], qvel[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        pos[t], rot[t], vel[t] = link_state(m, d, ids)
    return LinkMotion(tuple(links), pos, rot, vel)


def link_state(m: mujoco.MjModel, d: mujoco.MjData, ids: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(pos (K, 3), rot (K, 3, 3), vel (K, 3))`` of the bodies ``ids`` in ``d`` after ``mj_kinematics``,
    ``mj_comPos`` and ``mj_comVel`` (any model whose robot is one kinematic tree: a scene with objects too).
    ``vel`` is the body origin's linear velocity, ``v_c + w x (x - c)`` (the module docstring)."""
    vel = link_velocity(d.xpos[ids], d.cvel[ids], d.subtree_com[m.body_rootid[ids]])
    return d.xpos[ids].copy(), d.xmat[ids].reshape(len(ids), 3, 3).copy(), vel


def link_velocity(xpos, cvel, root_com):
    """(..., 3) a body origin's linear velocity ``v_c + w x (x - c)`` from MuJoCo's ``cvel`` (..., 6: angular, then
    linear, about the tree's centre of mass ``root_com`` (..., 3)) and the body position ``xpos`` (..., 3); numpy
    or torch alike (native MuJoCo and MuJoCo Warp store the same fields)."""
    w, r = cvel[..., :3], xpos - root_com
    cross = [w[..., 1] * r[..., 2] - w[..., 2] * r[..., 1], w[..., 2] * r[..., 0] - w[..., 0] * r[..., 2],
             w[..., 0] * r[..., 1] - w[..., 1] * r[..., 0]]  # fmt: skip
    return cvel[..., 3:] + namespace(xpos).stack(cross, -1)
