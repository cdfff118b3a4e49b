"""Every body of the G1 in mjlab's entity order, per frame, by forward kinematics of ``qpos`` and ``qvel``.

mjlab's tracking task (``mjlab/tasks/tracking/mdp/commands.py: MotionLoader``) loads ``body_pos_w``,
``body_quat_w``, ``body_lin_vel_w`` and ``body_ang_vel_w`` of shape ``[T, B, .]`` holding **every** body of the
robot entity, and picks its tracked bodies by the entity's body indices. The entity's bodies are its spec's bodies
after the world (``Entity.body_names`` = ``spec.bodies[1:]``), which for ``g1.xml`` is the compiled model's body order
1..30 (pelvis first; :data:`ENTITY_BODY_NAMES`); its joints are the spec's non-free joints (:data:`ENTITY_JOINT_NAMES`,
= :data:`pipeline.robot.G1_JOINT_NAMES`). mjlab's ``csv_to_npz.py`` records the entity's body *link* quantities:

* ``body_pos_w`` = ``xpos`` (the body frame's origin, world), ``body_quat_w`` = ``xquat`` (``wxyz``, world);
* ``body_ang_vel_w`` = ``cvel[:, 0:3]`` (world); ``body_lin_vel_w`` = the velocity of the body frame's origin,
  world: ``v_o = v_c + w x (p_o - c)`` with ``(w, v_c)`` = ``cvel`` (MuJoCo's com-based spatial velocity, taken at
  the subtree centre of mass ``c`` of the body's tree root) and ``p_o`` = ``xpos``.

Isaac Lab (BeyondMimic, HDMI) means something else by a body's linear velocity: ``body_lin_vel_w`` is the velocity of
the body's **centre of mass** (PhysX reports rigid bodies at their COM), ``v_com = v_c + w x (x_com - c)`` with
``x_com`` = ``xipos``: :attr:`BodyMotion.com_lin_vel`. Positions and orientations are the link frame's in both.

:func:`body_motion` sets ``qpos`` / ``qvel`` (root linear velocity world, root angular velocity in the root frame:
MuJoCo's free joint) on the robot model of :func:`pipeline.robot.g1_model` (mjlab's ``g1.xml`` without its visual
meshes: the same bodies, joints and inertias) and runs ``mj_kinematics``, ``mj_comPos`` and ``mj_comVel``.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.robot import G1_JOINT_NAMES, NQ_ROBOT, NV_ROBOT, g1_model


def _names() -> tuple[tuple[str, ...], tuple[str, ...]]:
    m = g1_model()
    bodies = tuple(m.body(i).name for i in range(1, m.nbody))
    joints = tuple(m.joint(j).name for j in range(m.njnt) if int(m.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_FREE))
    return bodies, joints


ENTITY_BODY_NAMES, ENTITY_JOINT_NAMES = _names()
#: column of each :data:`ENTITY_JOINT_NAMES` joint among ``qpos[:, 7:]`` (:data:`G1_JOINT_NAMES` order)
ENTITY_JOINT_INDEX = np.array([G1_JOINT_NAMES.index(n) for n in ENTITY_JOINT_NAMES])


@dataclass(frozen=True)
class BodyMotion:
    """Per frame and body (``[T, B, .]``, bodies :attr:`names`): world position [m], orientation (``wxyz``),
    linear velocity of the body frame's origin [m/s], angular velocity [rad/s] and linear velocity of the body's
    centre of mass [m/s] (Isaac Lab's ``body_lin_vel_w``), all in the world frame."""

    names: tuple[str, ...]
    pos: np.ndarray
    quat: np.ndarray
    lin_vel: np.ndarray
    ang_vel: np.ndarray
    com_lin_vel: np.ndarray

    @property
    def frames(self) -> int:
        return self.pos.shape[0]


def entity_joints(qpos_or_qvel_joints: np.ndarray) -> np.ndarray:
    """``[T, 29]`` joint columns (:data:`G1_JOINT_NAMES` order) in the entity's joint order."""
    return np.asarray(qpos_or_qvel_joints)[:, ENTITY_JOINT_INDEX]


def body_motion(qpos: np.ndarray, qvel: np.ndarray) -> BodyMotion:
    """Forward kinematics of ``qpos [T, 36]`` and ``qvel [T, 35]`` (the module doc) for every entity body."""
    qpos, qvel = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
    if qpos.shape[1:] != (NQ_ROBOT,) or qvel.shape != (qpos.shape[0], NV_ROBOT):
        raise ValueError(f"qpos {qpos.shape} / qvel {qvel.shape}: expected (T, {NQ_ROBOT}) / (T, {NV_ROBOT})")
    m = g1_model()
    d = mujoco.MjData(m)
    T, B = qpos.shape[0], m.nbody - 1
    pos, quat, cvel, com = np.empty((T, B, 3)), np.empty((T, B, 4)), np.empty((T, B, 6)), np.empty((T, B, 3))
    ipos = np.empty((T, B, 3))
    root = m.body_rootid[1:]
    for t in range(T):
        d.qpos[:], d.qvel[:] = qpos[t], qvel[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_comVel(m, d)
        pos[t], quat[t], cvel[t], com[t], ipos[t] = (
            d.xpos[1:],
            d.xquat[1:],
            d.cvel[1:],
            d.subtree_com[root],
            d.xipos[1:],
        )
    ang = cvel[..., 0:3]
    lin = cvel[..., 3:6] + np.cross(ang, pos - com)
    com_lin = cvel[..., 3:6] + np.cross(ang, ipos - com)
    return BodyMotion(ENTITY_BODY_NAMES, pos, quat, lin, ang, com_lin)
