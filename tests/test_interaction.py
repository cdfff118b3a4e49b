"""DF interaction features: the velocity decomposition, the surface-point velocity, the demo layout,
numpy = torch, and the representation's point: the same approach to a box scaled 0.4x-1.6x gives the
same hand phi / grad traces near contact."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from pipeline.distance.field import ObjectField
from pipeline.geometry import Primitive
from pipeline.rotations import wxyz_from_rotation
from pipeline.terms.interaction import demo_features, interaction_features, surface_point_velocity
from pipeline.terms.layout import feature_names


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def test_velocity_decomposition_is_orthogonal_and_complete():
    rng = np.random.default_rng(0)
    phi, grad, vel = rng.random((6, 4)), _unit(rng.normal(size=(6, 4, 3))), rng.normal(size=(6, 4, 3))
    u = interaction_features(phi, grad, vel)
    assert u.shape == (6, 4, 10)
    v_norm, v_tan = u[..., 4:7], u[..., 7:10]
    np.testing.assert_allclose(v_norm + v_tan, vel, atol=1e-12)
    np.testing.assert_allclose((v_tan * grad).sum(-1), 0, atol=1e-12)
    np.testing.assert_allclose(np.cross(v_norm, grad), 0, atol=1e-12)
    np.testing.assert_array_equal(u[..., 0], phi)
    ut = interaction_features(torch.from_numpy(phi), torch.from_numpy(grad), torch.from_numpy(vel))
    np.testing.assert_allclose(ut.numpy(), u, atol=1e-12)


def test_surface_point_velocity_matches_finite_differences():
    """A point fixed on a translating, spinning object moves at v_o + (R w_body) x (c - p_o)."""
    rng = np.random.default_rng(1)
    T, M, K, dt = 5, 2, 3, 1e-6
    rot = Rotation.from_rotvec(rng.normal(size=(T, M, 3)).reshape(-1, 3))
    poses = np.concatenate([rng.normal(size=(T * M, 3)), wxyz_from_rotation(rot)], 1).reshape(T, M, 7)
    vel = rng.normal(size=(T, M, 6))
    index = rng.integers(0, M, size=(T, K))
    local = rng.normal(size=(T, K, 3))  # surface points in their object's frame
    closest, moved = np.zeros((T, K, 3)), np.zeros((T, K, 3))
    for t in range(T):
        for k in range(K):
            m = index[t, k]
            r = Rotation.from_quat(np.roll(poses[t, m, 3:], -1))
            closest[t, k] = poses[t, m, :3] + r.apply(local[t, k])
            r2 = r * Rotation.from_rotvec(vel[t, m, 3:] * dt)  # body-frame angular velocity: right-multiplied
            moved[t, k] = poses[t, m, :3] + vel[t, m, :3] * dt + r2.apply(local[t, k])
    v = surface_point_velocity(closest, index, poses, vel)
    np.testing.assert_allclose(v, (moved - closest) / dt, atol=1e-4)
    vt = surface_point_velocity(*(torch.from_numpy(a) for a in (closest, index, poses, vel)))
    np.testing.assert_allclose(vt.numpy(), v, atol=1e-12)


def test_demo_layout_is_the_viewers_unsigned_field_clipped_and_in_the_body_frame():
    phi = np.array([[0.3, 2.5]])
    grad = np.array([[[1.0, 0, 0], [0, 0, 1.0]]])
    yaw90 = Rotation.from_euler("z", 90, degrees=True).as_matrix()  # body x-axis points along world y
    rot = np.stack([np.eye(3), yaw90])[None]
    d = demo_features(phi, grad, rot, max_distance=1.0)
    np.testing.assert_allclose(d[0, 0], [0.3, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(d[0, 1], [1.0, 0, 0, 0], atol=1e-12)  # beyond 1 m: the viewer's (1, 0, 0, 0)
    inside = demo_features(np.array([-0.05]), np.array([[0, 0, 1.0]]), np.eye(3)[None])  # unsigned: away from the face
    np.testing.assert_allclose(inside[0], [0.05, 0, 0, -1], atol=1e-12)
    world_x_in_yawed_body = demo_features(np.array([0.1]), np.array([[1.0, 0, 0]]), yaw90[None])
    np.testing.assert_allclose(world_x_in_yawed_body[0, 1:], [0, -1, 0], atol=1e-12)


def test_feature_names_are_per_link():
    names = feature_names(("pelvis", "torso_link"))
    assert (
        len(names) == 20
        and names[0] == "pelvis.phi"
        and names[10] == "torso_link.phi"
        and names[-1] == "torso_link.v_tan_z"
    )


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_same_approach_to_a_scaled_object_gives_the_same_traces_near_contact(shape):
    """A hand approaches the object's near face along -x at 0.5 m/s, the face always at x = 0 and centred
    on the hand: phi, grad and the velocity decomposition agree across scales 0.4, 1.0, 1.6 within 0.1 m."""
    base = Primitive(shape, (0.2, 0.25, 0.3) if shape == "box" else (0.2, 0.3))
    T = 50
    x = np.linspace(0.30, 0.0, T)
    hand = np.stack([x, np.zeros(T), np.full(T, 0.9)], 1)[:, None]  # (T, 1, 3)
    v = np.tile([-0.5, 0.0, 0.0], (T, 1, 1))
    traces = []
    for s in (0.4, 1.0, 1.6):
        geom = base.scaled(s)
        pose = np.tile([-float(geom.half_extents[0]), 0.0, 0.9, 1.0, 0.0, 0.0, 0.0], (T, 1))
        f = ObjectField.from_geometry(geom).query_links(hand, pose)
        traces.append(interaction_features(f.phi, f.grad, v)[:, 0])
    near = x <= 0.1
    for other in traces[1:]:
        np.testing.assert_allclose(other[near], traces[0][near], atol=1e-9)
    np.testing.assert_allclose(traces[0][:, 0], x, atol=1e-9)
    np.testing.assert_allclose(traces[0][near, 4:7], v[near, 0], atol=1e-9)  # all the motion is along the normal
