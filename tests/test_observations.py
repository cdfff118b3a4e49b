"""Policy observation terms: gravity in the root frame, proprio layout, the sparse root command."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.rotations import wxyz_from_rotation
from pipeline.terms.layout import PROPRIO_NAMES, ROOT_COMMAND_NAMES
from pipeline.terms.observations import (
    previous_actions,
    projected_gravity,
    proprioception,
    root_command,
    root_command_to,
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


def test_numpy_and_torch_give_the_same_terms():
    """The CPU environment (numpy) and the GPU backend (torch) share these functions: same rows, to float64 rounding."""
    import torch

    rng = np.random.default_rng(3)
    q, v, _ = _walk(6, yaw_deg=-120.0)
    q[:, 7:], v[:, 6:], v[:, 3:6] = rng.normal(size=(6, 29)), rng.normal(size=(6, 29)), rng.normal(size=(6, 3))
    target = np.roll(q, 2, axis=0)
    target[:, 3:7] = Rotation.random(6, random_state=1).as_quat()[:, [3, 0, 1, 2]]
    a = rng.normal(size=(6, 29))
    t = [torch.as_tensor(x) for x in (q, v, target, a)]
    np.testing.assert_allclose(proprioception(*t[:2], t[3]).numpy(), proprioception(q, v, a), atol=1e-12)
    np.testing.assert_allclose(
        root_command_to(t[0], t[2], t[1][:, :3]).numpy(), root_command_to(q, target, v[:, :3]), atol=1e-12
    )


def test_root_command_matches_scipy_rotations():
    """The heading-frame rotation written over arrays equals scipy's composition of rotations."""
    rng = np.random.default_rng(4)
    q = np.zeros((5, 36))
    q[:, :3] = rng.normal(size=(5, 3))
    q[:, 3:7] = Rotation.random(5, random_state=2).as_quat()[:, [3, 0, 1, 2]]
    target = q.copy()
    target[:, :3] += rng.normal(size=(5, 3))
    target[:, 3:7] = Rotation.random(5, random_state=3).as_quat()[:, [3, 0, 1, 2]]
    vel = rng.normal(size=(5, 3))
    x = Rotation.from_quat(q[:, [4, 5, 6, 3]]).apply([1.0, 0, 0])
    h_inv = Rotation.from_euler("z", np.arctan2(x[:, 1], x[:, 0])[:, None]).inv()
    R = (h_inv * Rotation.from_quat(target[:, [4, 5, 6, 3]])).as_matrix()
    want = np.concatenate([h_inv.apply(target[:, :3] - q[:, :3]), R[:, :, 0], R[:, :, 1], h_inv.apply(vel)], axis=1)
    np.testing.assert_allclose(root_command_to(q, target, vel), want, atol=1e-12)
