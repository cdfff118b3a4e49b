"""The static torques a tracked reference asks of the upper body's motors: a figure per clip.

The static torques ``tau_s`` (:mod:`pipeline.static_torque`) of the reference's poses, the hands
carrying the reaction of the grasp schedule's planned force. A ratio ``|tau_s| / tau_max`` above 1
means no controller can hold the reference still there, before the motion's own accelerations add
theirs. Measured on the feasible references of the bench clips with the synthetic box at 3 kg:
PickUp's waist pitch needs 0.72 x its 50 N m limit to hold the stoop over the box and 1.14 x with
the box in the hands (the tracker saturates it; the torso stays stooped while the reference stands
up with the box, which is lost); Carry's wrists 2.15 x; the valid Push and SitStand at most 0.64 x.
With the box at 1.5 kg (the default since), PickUp asks 0.93 x and is valid.
"""

from __future__ import annotations

import numpy as np

from pipeline.robot import G1_JOINT_NAMES
from pipeline.static_torque import UPPER_BODY_JOINTS, static_torques


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
