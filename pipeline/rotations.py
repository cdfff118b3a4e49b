"""Quaternion helpers. The project's convention is MuJoCo's: scalar first, ``wxyz``.

scipy's ``Rotation`` uses scalar-last ``xyzw``; :func:`xyzw_to_wxyz` and :func:`wxyz_to_xyzw` are
the only places the order is switched. :func:`quat_mat` and :func:`orientation_error` use MuJoCo's own
conversions (the controllers call them every step).
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


def quat_mat(q: np.ndarray) -> np.ndarray:
    """The rotation matrix (3, 3) of a unit quaternion ``q`` (wxyz)."""
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, q)
    return R.reshape(3, 3)
