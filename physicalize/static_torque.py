"""The static torques a tracked reference asks of the upper body's motors: a figure per clip.

A joint whose subtree touches nothing but what the hands hold (the waist and the arms) needs, to
hold a pose still, the static torque

    tau_s(q) = g(q) - sum_k J_k(q)^T w_k

(``g``: the generalized gravity force; ``w_k``: the force the held object exerts on hand ``k`` at its
hand point, the reaction of the grasp schedule's planned force; pinocchio's ``computeStaticTorque``
on the model built from the same MJCF). The legs are left out: theirs depend on how the weight splits
between the feet. A ratio ``|tau_s| / tau_max`` above 1 means no controller can hold the reference
still there, before the motion's own accelerations add theirs. Measured on the feasible references
of the bench clips with the synthetic box at 3 kg: PickUp's waist pitch needs 0.72 x its 50 N m limit
to hold the stoop over the box and 1.14 x with the box in the hands (the tracker saturates it; the
torso stays stooped while the reference stands up with the box, which is lost); Carry's wrists 2.15 x;
the valid Push and SitStand at most 0.64 x. With the box at 1.5 kg (the default since), PickUp asks
0.93 x and is valid.
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


def static_torque_figures(
    qpos: np.ndarray, hand_loads: tuple[np.ndarray, np.ndarray] | None, effort: np.ndarray, fps: float
) -> dict:
    """``reference_static_torque_ratio_max`` (max over frames and upper-body joints of ``|tau_s| / tau_max``;
    ``effort``: the 29 effort limits in :data:`pipeline.robot.G1_JOINT_NAMES` order),
    ``reference_static_torque_joint`` and ``reference_static_torque_at_s``: where it is;
    ``reference_static_torque_over_s``: how long some joint's ratio is above 1."""
    effort = np.asarray(effort, float)[[G1_JOINT_NAMES.index(j) for j in UPPER_BODY_JOINTS]]
    ratio = np.abs(static_torques(qpos, hand_loads)) / effort
    t, i = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return {
        "reference_static_torque_ratio_max": float(ratio[t, i]),
        "reference_static_torque_over_s": float((ratio.max(axis=1) > 1.0).sum() / fps),
        "reference_static_torque_joint": UPPER_BODY_JOINTS[i],
        "reference_static_torque_at_s": float(t / fps),
    }
