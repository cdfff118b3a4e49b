"""A held object's reference motion, as the object loop of the whole-body QP tracks it
(:mod:`physicalize.object_loop`): per control frame its centre of mass ``c`` with velocity and
acceleration, its orientation ``R`` with angular velocity and acceleration, and the contact mode its
reference implies (resting on its support, sliding on it).

Velocities are central differences of the track (``np.gradient``); the angular velocity is
``w_t = log(R_{t+1} R_{t-1}^T) / (2 dt)`` (one-sided at the ends), its acceleration the gradient of that.
A frame *rests* while the reference centre of mass is less than :data:`LIFT` above its lowest (on its support)
and not rising faster than :data:`RISE_SPEED` (the support then carries the part of the weight the hands do
not); it *slides* while resting and moving faster than :data:`SLIDE_SPEED` horizontally (the support's
friction then opposes the motion at full strength, ``mu f_n``, the kinetic friction of MuJoCo's soft
contacts)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.rotations import orientation_error, quat_mat

LIFT = 0.02  # m: a reference centre of mass this far above its lowest is carried, not resting
SLIDE_SPEED = 0.02  # m/s: a resting reference moving faster than this slides on its support
# m/s: a reference rising faster than this is being lifted, not resting (else the QP's support rows hold the object
# down through the first LIFT of a lift: the default PickUp's box lagged 13 cm and met the knees)
RISE_SPEED = 0.05


@dataclass(frozen=True)
class ObjectMotion:
    """The reference motion of one object over ``T`` frames (world frame)."""

    pos: np.ndarray  # (T, 3) the body frame's origin
    com: np.ndarray  # (T, 3)
    com_vel: np.ndarray
    com_acc: np.ndarray
    rot: np.ndarray  # (T, 3, 3)
    omega: np.ndarray  # (T, 3)
    alpha: np.ndarray  # (T, 3)
    rests: np.ndarray  # (T,) bool: on its support
    slides: np.ndarray  # (T,) bool: resting and moving along its support

    @classmethod
    def of(cls, pose: np.ndarray, ipos: np.ndarray, fps: float) -> ObjectMotion:
        """The motion of an object whose body frame follows ``pose`` (T, 7: position, quaternion wxyz) and
        whose centre of mass sits at ``ipos`` in that frame."""
        T, dt = len(pose), 1.0 / fps
        rot = np.stack([quat_mat(q) for q in pose[:, 3:7]])
        com = pose[:, :3] + rot @ ipos
        vel = np.gradient(com, dt, axis=0) if T > 1 else np.zeros_like(com)
        acc = np.gradient(vel, dt, axis=0) if T > 2 else np.zeros_like(com)
        omega = np.zeros((T, 3))
        for t in range(T):
            a, b = max(t - 1, 0), min(t + 1, T - 1)
            if b > a:
                omega[t] = orientation_error(rot[b], rot[a]) / ((b - a) * dt)
        alpha = np.gradient(omega, dt, axis=0) if T > 2 else np.zeros_like(omega)
        rests = (com[:, 2] - com[:, 2].min() < LIFT) & (vel[:, 2] < RISE_SPEED)
        slides = rests & (np.linalg.norm(vel[:, :2], axis=1) > SLIDE_SPEED)
        return cls(pose[:, :3].copy(), com, vel, acc, rot, omega, alpha, rests, slides)
