"""Policy observation terms: gravity in the root frame, proprio layout, the sparse root command."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.rotations import wxyz_from_rotation
from pipeline.terms.observations import (
    PROPRIO_NAMES,
    ROOT_COMMAND_NAMES,
    previous_actions,
    projected_gravity,
    proprioception,
    root_command,
)


def _walk(T=150, fps=50.0, yaw_deg=90.0, speed=1.0):
    """The root walks forward (along its own x-axis) at ``speed``, heading ``yaw_deg`` in the world, pitched 10 deg."""
    q, v = np.zeros((T, 36)), np.zeros((T, 35))
    r = Rotation.from_euler("ZY", [yaw_deg, 10.0], degrees=True)  # intrinsic: yaw, then pitch about the body y
    fwd = Rotation.from_euler("z", yaw_deg, degrees=True).apply([1.0, 0, 0])
    q[:, :3] = np.arange(T)[:, None] / fps * speed * fwd + [0, 0, 0.75]
    q[:, 3:7] = wxyz_from_rotation(r)
    v[:, :3] = speed * fwd
    return q, v, fps


def test_projected_gravity():
    q, _, _ = _walk(3, yaw_deg=0.0)
    np.testing.assert_allclose(
        projected_gravity(q[:1]), [Rotation.from_euler("y", 10, degrees=True).inv().apply([0, 0, -1])], atol=1e-12
    )
    q[:, 3:7] = [1.0, 0, 0, 0]
    np.testing.assert_allclose(projected_gravity(q), np.tile([0, 0, -1.0], (3, 1)), atol=1e-12)


def test_proprio_layout_and_last_action():
    rng = np.random.default_rng(0)
    q, v, _ = _walk(4)
    q[:, 7:], v[:, 6:], v[:, 3:6] = rng.normal(size=(4, 29)), rng.normal(size=(4, 29)), rng.normal(size=(4, 3))
    a = rng.normal(size=(4, 29))
    p = proprioception(q, v, previous_actions(a))
    assert p.shape == (4, 93) == (4, len(PROPRIO_NAMES))
    np.testing.assert_array_equal(p[:, :29], q[:, 7:])
    np.testing.assert_array_equal(p[:, 29:58], v[:, 6:])
    np.testing.assert_array_equal(p[:, 61:64], v[:, 3:6])
    np.testing.assert_array_equal(p[0, 64:], 0)
    np.testing.assert_array_equal(p[1:, 64:], a[:-1])
    assert PROPRIO_NAMES[64] == "last_action.left_hip_pitch_joint"


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, -135.0])
def test_root_command_is_in_the_heading_frame(yaw_deg):
    """Walking straight ahead at 1 m/s: the target 1 s ahead is 1 m forward, same orientation, 1 m/s
    forward, whatever the world heading; at the end of the clip the target is the last frame."""
    q, v, fps = _walk(yaw_deg=yaw_deg)
    c = root_command(q, v, fps, horizon_s=1.0)
    assert c.shape == (150, len(ROOT_COMMAND_NAMES))
    np.testing.assert_allclose(c[:100, :3], np.tile([1.0, 0, 0], (100, 1)), atol=1e-9)
    pitch = Rotation.from_euler("y", 10.0, degrees=True).as_matrix()
    np.testing.assert_allclose(c[:, 3:9], np.tile(np.concatenate([pitch[:, 0], pitch[:, 1]]), (150, 1)), atol=1e-9)
    np.testing.assert_allclose(c[:, 9:], np.tile([1.0, 0, 0], (150, 1)), atol=1e-9)
    np.testing.assert_allclose(c[-1, :3], 0, atol=1e-12)
    np.testing.assert_allclose(c[125, :3], [0.48, 0, 0], atol=1e-9)  # 24 frames to the end
