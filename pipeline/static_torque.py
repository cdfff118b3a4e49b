"""The static torques a robot pose asks of the upper body's motors while the hands hold a load.

A joint whose subtree touches nothing but what the hands hold (the waist and the arms) needs, to
hold a pose still, the static torque

    tau_s(q) = g(q) - sum_k J_k(q)^T w_k

(``g``: the generalized gravity force; ``w_k``: the force the held object exerts on hand ``k`` at its
hand point; pinocchio's ``computeStaticTorque`` on the model built from the same MJCF). The legs are
left out: theirs depend on how the weight splits between the feet. Shared by physicalize (its
reference's figure, :mod:`physicalize.static_torque`) and retarget (the heaviest object a variant's
poses can hold, :mod:`retarget.payload`).
"""

from __future__ import annotations

import numpy as np

from pipeline.robot import G1_JOINT_NAMES, HAND_BODIES, NQ_ROBOT, g1_pinocchio_model, pinocchio_qpos

UPPER_BODY_JOINTS = G1_JOINT_NAMES[G1_JOINT_NAMES.index("waist_yaw_joint") :]


def static_torques(
    qpos: np.ndarray,
    hand_loads: tuple[np.ndarray, np.ndarray] | None = None,
    joints: tuple[str, ...] = UPPER_BODY_JOINTS,
) -> np.ndarray:
    """``(T, len(joints))`` static torques [N m] of the robot poses ``qpos`` (T, 36), MuJoCo order.
    ``hand_loads``: ``(offset (2, 3), force (T, 2, 3))``, the force each hand (left, right) applies
    to what it holds at ``offset`` in its hand body's frame, world frame (the grasp schedule's
    ``offset`` and ``force``); the hands carry its reaction."""
    import pinocchio as pin

    model = g1_pinocchio_model()
    data = model.createData()
    dof = [model.joints[model.getJointId(j)].idx_v for j in joints]
    frames = [model.frames[model.getFrameId(b)] for b in HAND_BODIES]
    out = np.zeros((len(qpos), len(joints)))
    for t, q in enumerate(pinocchio_qpos(np.asarray(qpos)[:, :NQ_ROBOT])):
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        if hand_loads is not None and np.any(hand_loads[1][t]):
            pin.forwardKinematics(model, data, q)
            for k, frame in enumerate(frames):
                j = frame.parentJoint
                point = frame.placement.act(np.asarray(hand_loads[0][k], float))  # in the joint's frame
                local = data.oMi[j].rotation.T @ -np.asarray(hand_loads[1][t, k], float)
                fext[j] = fext[j] + pin.Force(local, np.cross(point, local))
        out[t] = pin.computeStaticTorque(model, data, q, fext)[dof]
    return out
