"""Link kinematics from MuJoCo: velocities agree with finite differences of positions; bad names fail."""

import mujoco
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.robot import G1_LINK_NAMES, actuator_profile, default_qpos, g1_model
from pipeline.terms.link_motion import link_motion


def _trajectory(T=40, fps=200.0):
    """A smooth whole-body motion: the root translates and turns, every joint swings."""
    t = np.arange(T) / fps
    q = np.repeat(default_qpos(actuator_profile("mjlab"))[None], T, 0)
    q[:, 0] += 0.4 * t
    q[:, 1] += 0.1 * np.sin(3 * t)
    yaw, roll = 0.8 * t, 0.1 * np.sin(5 * t)
    q[:, 3:7] = np.stack(
        [
            np.cos(yaw / 2) * np.cos(roll / 2),
            np.cos(yaw / 2) * np.sin(roll / 2),
            -np.sin(yaw / 2) * np.sin(roll / 2),
            np.sin(yaw / 2) * np.cos(roll / 2),
        ],
        1,
    )
    q[:, 7:] += 0.3 * np.sin(2 * t[:, None] + np.arange(29))
    m = g1_model()
    v = np.zeros((T, 35))
    for k in range(T):
        a, b = max(k - 1, 0), min(k + 1, T - 1)
        mujoco.mj_differentiatePos(m, v[k], (b - a) / fps, q[a], q[b])
    return q, v, fps


def test_link_velocity_matches_finite_differences_of_positions():
    q, v, fps = _trajectory()
    motion = link_motion(q, v, G1_LINK_NAMES)
    assert motion.pos.shape == (40, 14, 3) and motion.rot.shape == (40, 14, 3, 3)
    fd = (motion.pos[2:] - motion.pos[:-2]) * fps / 2
    np.testing.assert_allclose(motion.vel[1:-1], fd, atol=5e-3)
    np.testing.assert_allclose(
        np.einsum("tkij,tkil->tkjl", motion.rot, motion.rot), np.broadcast_to(np.eye(3), (40, 14, 3, 3)), atol=1e-9
    )
    assert np.abs(motion.vel).max() > 0.3  # the test moves the links


def test_unknown_link_and_bad_shapes_are_one_line_errors():
    q, v, _ = _trajectory(3)
    with pytest.raises(InputError, match="'left_hand' is not a body of the G1"):
        link_motion(q, v, ("pelvis", "left_hand"), "take.npz")
    with pytest.raises(InputError, match="qpos/qvel"):
        link_motion(q, v[:, :30], ("pelvis",))
