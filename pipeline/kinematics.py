"""G1 velocities from a ``qpos`` trajectory by finite differences (no model needed).

``qpos`` (36) is MuJoCo's G1 layout (:mod:`pipeline.robot`): root position (world), root
quaternion wxyz, 29 joint angles; ``qvel`` (35): root linear velocity (world), root angular
velocity (root frame, :func:`pipeline.rotations.quat_velocity`), joint velocities. The
dataset writers (:mod:`pipeline.dataset.clips`) and physicalize's reference use these.
"""

from __future__ import annotations

import numpy as np

from pipeline.rotations import quat_velocity


def qpos_difference(q1: np.ndarray, q2: np.ndarray, dt: float) -> np.ndarray:
    """``mj_differentiatePos`` for the G1 layout: ``(..., 36), (..., 36) -> (..., 35)``."""
    return np.concatenate(
        [
            (q2[..., :3] - q1[..., :3]) / dt,
            quat_velocity(q1[..., 3:7], q2[..., 3:7], dt),
            (q2[..., 7:] - q1[..., 7:]) / dt,
        ],
        axis=-1,
    )


def qvel_from_qpos(qpos: np.ndarray, fps: float) -> np.ndarray:
    """``(T, nq - 1)`` velocities (35 for the robot, 6 for a free object): the mean of the backward and forward
    differences (central), one-sided at the first and last frame, zeros for a one-frame clip."""
    qpos = np.asarray(qpos, dtype=np.float64)
    if qpos.shape[0] < 2:
        return np.zeros((qpos.shape[0], qpos.shape[1] - 1))
    d = qpos_difference(qpos[:-1], qpos[1:], 1.0 / fps)
    return np.concatenate([d[:1], 0.5 * (d[:-1] + d[1:]), d[-1:]], axis=0)
