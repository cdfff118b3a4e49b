"""Shared check for the fused warp ``*_world`` kernels: a pose per frame through ``query_links`` equals
the numpy pose transform of per-point poses."""

import numpy as np

from pipeline.distance.field import ObjectField
from pipeline.rotations import rotation_rows


def check_pose_per_frame(field: ObjectField, local: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Object-frame ``local`` (T, K, 3) at ``poses`` (T, 7): ``query_links`` (fused) equals ``query`` with the
    poses repeated per point (numpy) to 1e-9, shapes included; no links gives empty fields. Returns the
    world points (T, K, 3)."""
    frames, links = local.shape[:2]
    R = np.stack([np.stack(r, -1) for r in rotation_rows(poses[:, 3:], np)], -2)
    world = np.einsum("tij,tkj->tki", R, local) + poses[:, None, :3]
    fused = field.query_links(world, poses)
    ref = field.query(world.reshape(-1, 3), np.repeat(poses, links, axis=0))
    assert fused.phi.shape == (frames, links) and fused.grad.shape == fused.closest.shape == (frames, links, 3)
    for a, b in zip(fused, ref):
        np.testing.assert_allclose(a.reshape(b.shape), b, rtol=0, atol=1e-9)
    empty = field.query_links(np.zeros((3, 0, 3)), poses[:3])
    assert empty.phi.shape == (3, 0) and empty.closest.shape == (3, 0, 3)
    return world
