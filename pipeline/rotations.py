"""Quaternion helpers. The project's convention is MuJoCo's: scalar first, ``wxyz``.

scipy's ``Rotation`` uses scalar-last ``xyzw``; :func:`xyzw_to_wxyz` and :func:`wxyz_to_xyzw` are
the only places the order is switched. :func:`quat_mat` and :func:`orientation_error` use MuJoCo's own
conversions (the controllers call them every step); :func:`quat_velocity` is MuJoCo's ``mju_subQuat``
vectorised over frames (:mod:`pipeline.kinematics` differentiates whole trajectories with it).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q)
    return np.concatenate([q[..., 3:4], q[..., 0:3]], axis=-1)


def wxyz_to_xyzw(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def rotation_from_wxyz(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(wxyz_to_xyzw(np.asarray(q, dtype=np.float64).reshape(-1, 4)))


def wxyz_from_rotation(r: Rotation) -> np.ndarray:
    """Unit quaternions with a non-negative scalar part (one of the two covers, chosen canonically)."""
    q = xyzw_to_wxyz(r.as_quat())
    return np.where(q[..., :1] < 0, -q, q)


def slerp_wxyz(times: np.ndarray, q: np.ndarray, new_times: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation of a (T,4) wxyz track at ``new_times`` (inside ``times``)."""
    return wxyz_from_rotation(Slerp(times, rotation_from_wxyz(q))(new_times))


# Rotation taking a y-up frame to a z-up one: +90 deg about x (y -> z, z -> -y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def yaw_of(quat_wxyz: np.ndarray) -> np.ndarray:
    """The heading [rad] (rotation about the world z axis) of wxyz quaternions ``(..., 4)``:
    ``atan2(2 (w z + x y), 1 - 2 (y^2 + z^2))``."""
    w, x, y, z = np.moveaxis(np.asarray(quat_wxyz), -1, 0)
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def yaw_quat(yaw: float) -> np.ndarray:
    """The unit quaternion (wxyz) of a rotation by ``yaw`` [rad] about the world z axis."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def orientation_error(R_ref: np.ndarray, R: np.ndarray) -> np.ndarray:
    """World-frame rotation vector ``log(R_ref R^T)`` taking ``R`` to ``R_ref``."""
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, (R_ref @ R.T).ravel())
    v = np.empty(3)
    mujoco.mju_quat2Vel(v, q, 1.0)
    return v


def pose_rotations(pose: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotation matrices of (T, 7) poses ``(x, y, z, qw, qx, qy, qz)``."""
    return rotation_from_wxyz(pose[:, 3:7]).as_matrix()


def to_pose_frame(pose: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(T, 3) world points ``p`` in the frames of (T, 7) ``pose``: ``R_t^T (p_t - c_t)``."""
    return np.einsum("tji,tj->ti", pose_rotations(pose), p - pose[:, :3])


def from_pose_frame(pose: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(T, 3) points ``u`` of the frames of (T, 7) ``pose`` in the world: ``c_t + R_t u_t``."""
    return pose[:, :3] + np.einsum("tij,tj->ti", pose_rotations(pose), u)


def quat_mat(q: np.ndarray) -> np.ndarray:
    """The rotation matrix (3, 3) of a unit quaternion ``q`` (wxyz)."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, q)
    return R.reshape(3, 3)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_velocity(q1: np.ndarray, q2: np.ndarray, dt: float) -> np.ndarray:
    """Angular velocity (rad/s, in the frame of ``q1``, equally of ``q2``) turning ``q1`` into ``q2`` in ``dt``.

    ``dq = conj(q1) * q2``; the result is ``axis * angle / dt`` with the angle wrapped to
    ``[-pi, pi]`` (the shorter way) -- MuJoCo's ``mju_subQuat`` / ``mju_quat2Vel``.
    """
    q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    q2 = q2 / np.linalg.norm(q2, axis=-1, keepdims=True)
    dq = _quat_mul(q1 * np.array([1.0, -1.0, -1.0, -1.0]), q2)
    dq = np.where(dq[..., :1] < 0, -dq, dq)
    v = dq[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, dq[..., :1])
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0)
    return v * scale / dt


def rotation_rows(q, xp):
    """Rows of R for wxyz quaternions q (..., 4), normalised; entries are scalars or arrays."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    n = xp.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )
