"""Policy observation terms of a G1 trajectory, as plain functions (mjlab style).

* :func:`proprioception` (93 per frame): joint angles (29), joint velocities (29), gravity in the
  root frame (3), root angular velocity in the root frame (3), the previous frame's action (29;
  zeros at the first frame) -- the released LessMimic demo's per-frame proprio layout.
* :func:`root_command` (12 per frame): the sparse target root trajectory ``c_root`` -- the root at
  ``t + horizon`` seen from the root's heading frame at ``t`` (yaw only, z up): position delta (3),
  orientation as the first two columns of ``H_t^T R_target`` (6-D rotation, column-major), and the
  root's linear velocity at the target in the heading frame (3) -- the demo's 12-d movement goal.
  Near the end of a clip the target is the last frame.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.robot import G1_JOINT_NAMES, JOINTS_QPOS, JOINTS_QVEL, ROOT_ANG_VEL
from pipeline.rotations import rotation_from_wxyz

PROPRIO_NAMES: tuple[str, ...] = (
    tuple(f"q.{j}" for j in G1_JOINT_NAMES)
    + tuple(f"dq.{j}" for j in G1_JOINT_NAMES)
    + ("gravity_x", "gravity_y", "gravity_z")
    + ("ang_vel_x", "ang_vel_y", "ang_vel_z")
    + tuple(f"last_action.{j}" for j in G1_JOINT_NAMES)
)
ROOT_COMMAND_NAMES: tuple[str, ...] = (
    "dpos_x",
    "dpos_y",
    "dpos_z",
    "rot6d_0",
    "rot6d_1",
    "rot6d_2",
    "rot6d_3",
    "rot6d_4",
    "rot6d_5",
    "vel_x",
    "vel_y",
    "vel_z",
)


def rot6(R: np.ndarray) -> np.ndarray:
    """(..., 6) the 6-D rotation of rotation matrices ``R`` (..., 3, 3): their first two columns, column-major."""
    return np.swapaxes(R[..., :, :2], -1, -2).reshape(*R.shape[:-2], 6)


def projected_gravity(qpos: np.ndarray) -> np.ndarray:
    """(T, 3) unit gravity direction in the root frame, ``R_root^T (0, 0, -1)``."""
    return rotation_from_wxyz(qpos[:, 3:7]).inv().apply([0.0, 0.0, -1.0])


def previous_actions(action: np.ndarray) -> np.ndarray:
    """(T, 29) the action of the frame before each frame of a clip (zeros before the first)."""
    return np.concatenate([np.zeros((1, action.shape[1])), action[:-1]])


def proprioception(qpos: np.ndarray, qvel: np.ndarray, last_action: np.ndarray) -> np.ndarray:
    """(N, 93) ``[q, dq, gravity_root, omega_root, a_(t-1)]`` from ``qpos (N, 36)``, MuJoCo ``qvel (N, 35)``
    (its root angular velocity is already in the root frame) and the previous actions ``last_action (N, 29)``
    (the rows are a clip's frames, with :func:`previous_actions`, or an environment batch)."""
    return np.concatenate(
        [qpos[:, JOINTS_QPOS], qvel[:, JOINTS_QVEL], projected_gravity(qpos), qvel[:, ROOT_ANG_VEL], last_action],
        axis=1,
    )


def heading(qpos: np.ndarray) -> Rotation:
    """The root's heading frame per frame: the rotation about z by the yaw of the root's x-axis."""
    x = rotation_from_wxyz(qpos[:, 3:7]).apply([1.0, 0.0, 0.0])
    return Rotation.from_euler("z", np.arctan2(x[:, 1], x[:, 0])[:, None])


def root_command_to(qpos: np.ndarray, target_qpos: np.ndarray, target_vel: np.ndarray) -> np.ndarray:
    """(N, 12) ``[H^T (p* - p), rot6d(H^T R*), H^T v*]``: the target root (position ``p*``, orientation ``R*`` of
    ``target_qpos (N, 7+)``, linear velocity ``v* (N, 3)``) seen from the heading frame ``H`` of ``qpos (N, 7+)``."""
    h_inv = heading(qpos).inv()
    dpos = h_inv.apply(target_qpos[:, :3] - qpos[:, :3])
    rot6d = rot6((h_inv * rotation_from_wxyz(target_qpos[:, 3:7])).as_matrix())
    return np.concatenate([dpos, rot6d, h_inv.apply(target_vel[:, :3])], axis=1)


def command_frames(frames: int, fps: float, horizon_s: float = 1.0) -> np.ndarray:
    """(T,) the frame ``j = min(t + horizon fps, T - 1)`` each frame's root command looks at."""
    return np.minimum(np.arange(frames) + int(round(horizon_s * fps)), frames - 1)


def root_command(qpos: np.ndarray, qvel: np.ndarray, fps: float, horizon_s: float = 1.0) -> np.ndarray:
    """(T, 12) a clip's own root commands: :func:`root_command_to` frame ``j`` of :func:`command_frames`."""
    j = command_frames(len(qpos), fps, horizon_s)
    return root_command_to(qpos, qpos[j], qvel[j, :3])
