"""Value ranges per column, checked when a dataset is written and when it is verified.

Why: a finite number can still be impossible (a joint velocity of 344 rad/s from a flipped byte, a root that jumps
10,000 km, a joint bent past its stop), and a checksum only says the bytes are those written, not that they make
sense. The bounds are the G1's own with a margin no valid clip comes near (the default corpus's extremes, measured:
joints 0.016 rad past a stop in simulation, 0.5 of the rated motor speed, the root at 3 m/s, torques at the effort
limit); a value past one is an :class:`InputError` naming the episode, the frame, the column and the bound.

By column name (any dataset; a column the table does not name is only checked finite):

* ``observation.state`` / ``reference.state`` (G1 qpos, 36): joints within their range +-
  :data:`JOINT_MARGIN_RAD`, a unit root quaternion, the root within :data:`MAX_POSITION_M` of the origin and moving
  at most :data:`MAX_ROOT_SPEED_MPS` between frames;
* ``observation.qvel`` (35): root linear speed <= :data:`MAX_ROOT_SPEED_MPS`, root angular speed <=
  :data:`MAX_ANGULAR_SPEED_RADPS`, joint speeds <= :data:`MOTOR_SPEED_FACTOR` x the rated motor speed;
* ``observation.torque`` (29): within the effort limit + :data:`TORQUE_MARGIN` (the actuators clip to it);
* ``*.pose`` (7: position, quaternion) and ``observation.joint_quat`` (4 per joint): unit quaternions, positions
  within :data:`MAX_POSITION_M`; ``observation.joint_pos``: within :data:`MAX_POSITION_M`.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import numpy as np

from pipeline.errors import InputError, first_bad_frame

JOINT_MARGIN_RAD = 0.25
MAX_ROOT_SPEED_MPS = 15.0
MAX_ANGULAR_SPEED_RADPS = 60.0
MOTOR_SPEED_FACTOR = 3.0
TORQUE_MARGIN = 1.05
MAX_POSITION_M = 1000.0
QUAT_NORM_TOL = 1e-3
NQ, NV, NJ = 36, 35, 29


@lru_cache(maxsize=1)
def _g1_bounds() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper) joint ranges with the margin, joint speed and torque bounds, in the G1's joint order."""
    from pipeline.robot import EFFORT_LIMIT, joint_limits, joint_velocity_limits

    lo, hi = joint_limits()
    speed = np.array(list(joint_velocity_limits(MOTOR_SPEED_FACTOR).values()))
    return lo - JOINT_MARGIN_RAD, hi + JOINT_MARGIN_RAD, speed, EFFORT_LIMIT * TORQUE_MARGIN


def _fail(where: str, column: str, bad: np.ndarray, values: np.ndarray, what: str) -> None:
    if bad.any():
        k = first_bad_frame(bad)
        j = int(np.flatnonzero(bad[k].reshape(-1))[0]) if bad.ndim > 1 else 0
        value = float(np.asarray(values[k]).reshape(-1)[j])
        raise InputError(where, column, f"element {j} is {value:.6g}: {what}", frame=k)


def _quats(where: str, column: str, q: np.ndarray) -> None:
    norm = np.linalg.norm(q.reshape(len(q), -1, 4), axis=-1)
    _fail(where, column, np.abs(norm - 1) > QUAT_NORM_TOL, norm, "quaternion norm is not 1")


def _positions(where: str, column: str, p: np.ndarray) -> None:
    _fail(where, column, np.abs(p) > MAX_POSITION_M, p, f"farther than {MAX_POSITION_M:g} m from the origin")


def _qpos(where: str, column: str, q: np.ndarray, fps: float) -> None:
    lo, hi, _, _ = _g1_bounds()
    joints = q[:, 7:]
    out = (joints < lo) | (joints > hi)
    _fail(
        where, column, np.pad(out, ((0, 0), (7, 0))), q, f"a joint past its range by more than {JOINT_MARGIN_RAD} rad"
    )
    _positions(where, column, q[:, :3])
    _quats(where, column, q[:, 3:7])
    step = np.linalg.norm(np.diff(q[:, :3].astype(np.float64), axis=0), axis=1) * fps
    bad = np.concatenate([[False], step > MAX_ROOT_SPEED_MPS])
    _fail(where, column, bad, np.concatenate([[0.0], step]), f"the root moves faster than {MAX_ROOT_SPEED_MPS} m/s")


def _qvel(where: str, column: str, v: np.ndarray) -> None:
    _, _, speed, _ = _g1_bounds()
    lin, ang = np.linalg.norm(v[:, :3], axis=1), np.abs(v[:, 3:6])
    _fail(where, column, lin > MAX_ROOT_SPEED_MPS, lin, f"root speed above {MAX_ROOT_SPEED_MPS} m/s")
    _fail(
        where, column, ang > MAX_ANGULAR_SPEED_RADPS, ang, f"root turning faster than {MAX_ANGULAR_SPEED_RADPS} rad/s"
    )
    fast = np.pad(np.abs(v[:, 6:]) > speed, ((0, 0), (6, 0)))
    _fail(where, column, fast, v, f"a joint faster than {MOTOR_SPEED_FACTOR:g} x its rated motor speed")


def check_ranges(data: Mapping[str, np.ndarray], fps: float, where: str) -> None:
    """Check one episode's ``{column: (T, dim)}`` (see the module docstring); ``where`` names the dataset and
    episode in the error."""
    for column, a in data.items():
        if a.dtype.kind != "f":
            continue
        _fail(where, column, ~np.isfinite(a), a, "NaN or infinite")
        dim = a.shape[1]
        if column in ("observation.state", "reference.state") and dim == NQ:
            _qpos(where, column, a, fps)
        elif column == "observation.qvel" and dim == NV:
            _qvel(where, column, a)
        elif column == "observation.torque" and dim == NJ:
            limit = _g1_bounds()[3]
            _fail(where, column, np.abs(a) > limit, a, f"beyond {TORQUE_MARGIN:g} x the joint's effort limit")
        elif column.endswith(".pose") and dim % 7 == 0:
            poses = a.reshape(len(a), -1, 7)
            _positions(where, column, poses[..., :3])
            _quats(where, column, poses[..., 3:])
        elif column == "observation.joint_quat" and dim % 4 == 0:
            _quats(where, column, a)
        elif column == "observation.joint_pos":
            _positions(where, column, a)
