"""The warp kernels of the scaled sphere, cylinder and capsule against the numpy reference (``local_xp``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from fused_poses import check_pose_per_frame

from pipeline.distance.primitive import primitive_shape
from pipeline.geometry import Primitive

SCALED = [
    Primitive("sphere", (0.2,), (1.0, 1.5, 0.5)),
    Primitive("sphere", (0.2,), (1.0, 1.0, 0.5)),  # spheroid: two equal semi-axes
    Primitive("sphere", (0.2,), (2.0, 1.0, 1.0)),
    Primitive("cylinder", (0.1, 0.3), (2.0, 1.0, 0.7)),
    Primitive("capsule", (0.1, 0.2), (1.0, 1.0, 2.0)),  # circular section, prolate caps
    Primitive("capsule", (0.1, 0.2), (2.0, 1.5, 0.6)),  # flat caps: restricted normal points inside
    Primitive("capsule", (0.1, 0.05), (2.0, 2.0, 0.5)),
]


def _points(shape, n: int = 4000) -> np.ndarray:
    """Random points from the centre to far away, on the axes and symmetry planes, and on the surface."""
    rng = np.random.default_rng(7)
    ext = np.array([*shape.radii[:2], getattr(shape, "half_length", 0.0) + shape.radii[-1]])
    p = rng.uniform(-1.5, 1.5, (n, 3)) * ext
    k = n // 8
    p[:k, :2] = 0.0  # on the z axis
    p[k : 2 * k, 2] = 0.0  # on the x-y plane
    p[2 * k : 3 * k, 0] = 0.0
    p[3 * k : 4 * k, 1] = 0.0
    p[4 * k : 5 * k] *= 1e-7  # at the centre
    p[5 * k : 6 * k] *= 40.0  # far away
    p[6 * k] = 0.0
    phi, g, c = shape.local_xp(*p[7 * k :].T, np)
    p[7 * k :] = np.stack(c, 1)  # on the surface
    return p


@pytest.mark.parametrize("prim", SCALED, ids=lambda p: f"{p.kind}{p.scale}")
def test_warp_kernel_matches_the_numpy_reference(prim):
    shape = primitive_shape(prim)
    p = _points(shape)
    phi, g, c = shape.local(*p.T, np)
    rphi, rg, rc = shape.local_xp(*p.T, np)
    np.testing.assert_allclose(phi, rphi, rtol=0, atol=1e-12)
    # foot points and directions to 1e-8: near the top of a flat cap the numpy reference's foot
    # point is off the normal line by ~1e-8 (the kernel's is on it to rounding, checked below)
    c, g = np.stack(c, 1), np.stack(g, 1)
    np.testing.assert_allclose(c, np.stack(rc, 1), rtol=0, atol=1e-8)
    far = rphi > 1e-6
    np.testing.assert_allclose(g[far], np.stack(rg, 1)[far], rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(p - c, axis=1), phi, rtol=0, atol=1e-12)
    # p - c lies along grad (+-); to 1e-7 where a pole point stands in for a normal point next to it
    # (p within ~1e-7 of an axis: the distance is exact to rounding, the foot point to first order)
    r = (p - c)[far] / phi[far, None]
    assert np.abs(np.cross(r, g[far])).max() < 1e-7
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_torch_cpu_tensors_take_the_kernel_and_keep_their_dtype(dtype):
    shape = primitive_shape(SCALED[5])
    p = _points(shape, 800)
    phi, g, c = shape.local(*torch.as_tensor(p, dtype=dtype).T, torch)
    assert phi.dtype == dtype and g[0].dtype == dtype and c[2].dtype == dtype
    ref = shape.local_xp(*torch.as_tensor(p, dtype=dtype).to(torch.float64).T, torch)[0].numpy()
    np.testing.assert_allclose(phi.double().numpy(), ref, rtol=0, atol=1e-12 if dtype == torch.float64 else 1e-6)


def test_no_points():
    phi, g, c = primitive_shape(SCALED[0]).local(np.zeros(0), np.zeros(0), np.zeros(0), np)
    assert phi.shape == (0,) and g[0].shape == (0,) and c[0].shape == (0,)


@pytest.mark.parametrize("prim", SCALED, ids=lambda p: f"{p.kind}{p.scale}")
def test_pose_fused_kernel_equals_the_numpy_pose_transform(prim):
    """One numpy pose runs the pose in the kernel; a per-point pose (N, 7) transforms in numpy."""
    from pipeline.distance.field import ObjectField

    field = ObjectField.from_geometry(prim)
    rng = np.random.default_rng(11)
    local = _points(field.shape, 2000)
    for _ in range(4):
        pose = np.r_[rng.uniform(-2, 2, 3), rng.normal(size=4) * rng.uniform(0.2, 3.0)]  # quaternion not normalised
        world = local * rng.uniform(0.5, 1.5) + rng.uniform(-2, 2, 3)
        fused = field.query(world, pose)
        ref = field.query(world, np.tile(pose, (len(world), 1)))
        assert fused.grad.shape == ref.grad.shape == (len(world), 3) and fused.phi.shape == (len(world),)
        for a, b in zip(fused, ref):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    empty = field.query(np.zeros((0, 3)), pose)
    assert empty.phi.shape == (0,) and empty.closest.shape == (0, 3)


@pytest.mark.parametrize("prim", SCALED, ids=lambda p: f"{p.kind}{p.scale}")
def test_pose_per_frame_fused_kernel_equals_the_numpy_pose_transform(prim):
    """Links over frames (a pose per frame) run the poses in the kernel; per-point poses transform in numpy."""
    from pipeline.distance.field import ObjectField

    field = ObjectField.from_geometry(prim)
    rng = np.random.default_rng(12)
    frames, links = 50, 40
    local = _points(field.shape, frames * links)[rng.permutation(frames * links)].reshape(frames, links, 3)
    poses = np.c_[rng.uniform(-2, 2, (frames, 3)), rng.normal(size=(frames, 4)) * rng.uniform(0.2, 3.0, (frames, 1))]
    world = check_pose_per_frame(field, local, poses)
    one = field.query_links(world[:1], poses[:1])  # a single frame is the one-pose kernel
    np.testing.assert_allclose(one.phi[0], field.query(world[0], poses[0]).phi, rtol=0, atol=0)
    assert field.query_links(np.zeros((0, 5, 3)), np.zeros((0, 7))).grad.shape == (0, 5, 3)
