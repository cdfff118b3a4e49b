"""Policy observation terms of a G1 trajectory, as plain functions (mjlab style).

Their widths and element names are the contract of :mod:`pipeline.terms.layout`.

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

from pipeline.robot import JOINTS_QPOS, JOINTS_QVEL, ROOT_ANG_VEL
from pipeline.rotations import rotation_rows
from pipeline.terms.layout import ROOT_HORIZON_S
from pipeline.xp import concat, namespace


def rot6(R):
    """(..., 6) the 6-D rotation of rotation matrices ``R`` (..., 3, 3): their first two columns, column-major."""
    return concat([R[..., :, 0], R[..., :, 1]], namespace(R), axis=-1)


def rotation_matrix(quat):
    """(N, 3, 3) rotation matrices of wxyz quaternions ``quat`` (N, 4) (normalised first)."""
    xp = namespace(quat)
    return xp.stack([xp.stack(row, -1) for row in rotation_rows(quat, xp)], -2)


def projected_gravity(qpos):
    """(N, 3) unit gravity direction in the root frame, ``R_root^T (0, 0, -1)``: minus R's last row."""
    return -rotation_matrix(qpos[:, 3:7])[:, 2, :]


def previous_actions(action):
    """(T, 29) the action of the frame before each frame of a clip (zeros before the first)."""
    return concat([action[:1] * 0, action[:-1]], namespace(action))


def proprioception(qpos, qvel, last_action):
    """(N, 93) ``[q, dq, gravity_root, omega_root, a_(t-1)]`` from ``qpos (N, 36)``, MuJoCo ``qvel (N, 35)``
    (its root angular velocity is already in the root frame) and the previous actions ``last_action (N, 29)``
    (the rows are a clip's frames, with :func:`previous_actions`, or an environment batch); numpy or torch alike
    (:mod:`pipeline.xp`), so the CPU and GPU environments share it."""
    parts = [qpos[:, JOINTS_QPOS], qvel[:, JOINTS_QVEL], projected_gravity(qpos), qvel[:, ROOT_ANG_VEL], last_action]
    return concat(parts, namespace(qpos), axis=1)


def heading_yaw(qpos):
    """(N,) the root's heading: the yaw of the root's x-axis about z."""
    R = rotation_matrix(qpos[:, 3:7])
    return namespace(qpos).arctan2(R[:, 1, 0], R[:, 0, 0])


def to_heading(v, yaw):
    """(N, 3, ...) vectors ``v`` (N, 3, ...) in the world seen from the heading frame of ``yaw`` (N,)."""
    xp = namespace(v)
    shape = (-1, *(1,) * (v.ndim - 2))
    c, s = xp.cos(yaw).reshape(shape), xp.sin(yaw).reshape(shape)
    return xp.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]], 1)


def root_command_to(qpos, target_qpos, target_vel):
    """(N, 12) ``[H^T (p* - p), rot6d(H^T R*), H^T v*]``: the target root (position ``p*``, orientation ``R*`` of
    ``target_qpos (N, 7+)``, linear velocity ``v* (N, 3)``) seen from the heading frame ``H`` of ``qpos (N, 7+)``."""
    yaw = heading_yaw(qpos)
    dpos = to_heading(target_qpos[:, :3] - qpos[:, :3], yaw)
    rot = to_heading(rotation_matrix(target_qpos[:, 3:7]), yaw)
    return concat([dpos, rot6(rot), to_heading(target_vel[:, :3], yaw)], namespace(qpos), axis=1)


def demo_command(root_command, task_value):
    """(N, 14) the demo contract's command (:data:`pipeline.terms.layout.CONTRACTS`): ``root_command (N, 12)`` with
    its height delta and vertical velocity zeroed (the released viewer's movement goal has z = 0) and the task
    condition ``[v, v]`` of ``task_value (N,)`` appended (the viewer writes one value into both slots)."""
    xp = namespace(root_command)
    keep = xp.ones(root_command.shape[-1], dtype=root_command.dtype)
    keep[2] = keep[11] = 0.0
    v = xp.reshape(task_value, (-1, 1)) + 0.0 * root_command[:, :1]
    return concat([root_command * keep, v, v], xp, axis=1)


def command_frames(frames: int, fps: float, horizon_s: float = ROOT_HORIZON_S) -> np.ndarray:
    """(T,) the frame ``j = min(t + horizon fps, T - 1)`` each frame's root command looks at."""
    return np.minimum(np.arange(frames) + int(round(horizon_s * fps)), frames - 1)


def root_command(qpos: np.ndarray, qvel: np.ndarray, fps: float, horizon_s: float = ROOT_HORIZON_S) -> np.ndarray:
    """(T, 12) a clip's own root commands: :func:`root_command_to` frame ``j`` of :func:`command_frames`."""
    j = command_frames(len(qpos), fps, horizon_s)
    return root_command_to(qpos, qpos[j], qvel[j, :3])
