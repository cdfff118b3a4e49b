"""Isaac Lab's joint and body order for the G1: the order BeyondMimic's motion ``.npz`` holds its columns in.

BeyondMimic (``HybridRobotics/whole_body_tracking``, ``scripts/csv_to_npz.py``) replays a motion on its Isaac Lab G1
(``robots/g1.py: G1_CYLINDER_CFG``, Unitree's ``g1/main.urdf``, fixed joints merged away) and saves
``robot.data.joint_pos`` / ``joint_vel`` and ``robot.data.body_pos_w`` / ``body_quat_w`` / ``body_lin_vel_w`` /
``body_ang_vel_w`` for **all** joints and bodies, in the articulation's own order; its ``MotionLoader``
(``tasks/tracking/mdp/commands.py``) reads the columns by the indices ``robot.find_joints`` / ``robot.find_bodies``
give in that same articulation, never by name (the file has no name keys). PhysX orders an articulation's links
**breadth-first** from the root (level by level; within a level by parent, then in the description's child order)
and its joints as their child links. On the G1 (30 links, 29 revolute joints) that is :data:`ISAACLAB_BODY_NAMES`
and :data:`ISAACLAB_JOINT_NAMES` (:mod:`pipeline.isaaclab_order`) -- the order a BeyondMimic policy's exported
``joint_names`` list too.

mjlab (MuJoCo) orders the same bodies depth-first (:data:`motion_export.bodies.ENTITY_BODY_NAMES`): only 2 of the 29
joint columns coincide, so an mjlab file read by BeyondMimic drives the wrong joints. Both tables are kept literally
here (the order a file is written in must not move with a model file) and checked against a breadth-first walk of
the compiled G1 model (:func:`breadth_first_names`) by the tests.
"""

from __future__ import annotations

from collections import deque

import mujoco
import numpy as np

from motion_export.bodies import ENTITY_BODY_NAMES, ENTITY_JOINT_NAMES
from pipeline.isaaclab_order import ISAACLAB_BODY_NAMES, ISAACLAB_JOINT_NAMES
from pipeline.robot import g1_model

#: column of each :data:`ISAACLAB_JOINT_NAMES` joint among the entity's (mjlab) joints
ISAACLAB_JOINT_INDEX = np.array([ENTITY_JOINT_NAMES.index(n) for n in ISAACLAB_JOINT_NAMES])
#: index of each :data:`ISAACLAB_BODY_NAMES` body among the entity's (mjlab) bodies
ISAACLAB_BODY_INDEX = np.array([ENTITY_BODY_NAMES.index(n) for n in ISAACLAB_BODY_NAMES])


def breadth_first_names() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(bodies, joints)`` of the compiled G1 model walked breadth-first from the pelvis, children in the model's
    order, each body's joint named with it (the free joint left out): how PhysX orders the articulation."""
    m = g1_model()
    children: dict[int, list[int]] = {}
    for b in range(2, m.nbody):
        children.setdefault(int(m.body_parentid[b]), []).append(b)
    bodies, queue = [], deque([1])
    while queue:
        b = queue.popleft()
        bodies.append(b)
        queue.extend(children.get(b, []))
    joints = []
    for b in bodies:
        for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
            if int(m.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_FREE):
                joints.append(m.joint(j).name)
    return tuple(m.body(b).name for b in bodies), tuple(joints)
