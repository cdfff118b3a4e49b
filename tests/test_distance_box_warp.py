"""The fused warp kernels of the box and the chair (union of boxes) against the numpy ``local`` field."""

from __future__ import annotations

import numpy as np
import pytest
from fused_poses import check_pose_per_frame

from pipeline.distance.field import ObjectField
from pipeline.distance.primitive import box_phi, chair_shape, primitive_shape
from pipeline.geometry import Chair, Primitive

BOXES = [
    Primitive("box", (0.3, 0.2, 0.1)),
    Primitive("box", (0.3, 0.2, 0.1), (1.6, 0.4, 1.0)),
    Primitive("box", (0.2, 0.2, 0.2)),  # a cube: inside, faces tie along the diagonals
]
IDENTITY = (np.eye(3)[None], np.zeros((1, 3)))


def _box_points(half, n: int = 4000) -> np.ndarray:
    """Random points inside and out; on faces, edges and corners; on the diagonals (face ties); at the centre."""
    rng = np.random.default_rng(5)
    h = np.asarray(half)
    p = rng.uniform(-2.0, 2.0, (n, 3)) * h
    k = n // 8
    signs = rng.choice([-1.0, 1.0], (n, 3))
    axis = rng.integers(0, 3, n)
    face = np.arange(k, 2 * k)
    p[face, axis[face]] = (signs * h)[face, axis[face]]  # on a face plane (on the face, or beside it)
    edge = np.arange(2 * k, 3 * k)
    p[edge] = np.where(np.arange(3) == axis[edge, None], p[edge], signs[edge] * h)  # on an edge line
    p[3 * k : 4 * k] = signs[3 * k : 4 * k] * h  # corners
    diag = rng.uniform(0.0, 1.0, (k, 1)) * h.min()
    p[4 * k : 5 * k] = signs[4 * k : 5 * k] * (h - diag)  # equal depth below all three faces
    p[5 * k : 6 * k] = 0.0
    p[5 * k : 6 * k, 0] = rng.uniform(-1.0, 1.0, k) * h[0]  # on the box's mid planes
    p[6 * k : 7 * k] *= 1e-9  # next to the centre
    return p


def _chair_points(chair: Chair, n: int = 6000) -> np.ndarray:
    """Random points around the chair; each part's faces, edges, corners; points equidistant from two legs."""
    shape = chair_shape(chair)
    rng = np.random.default_rng(6)
    hd, hw = chair.seat_depth / 2, chair.seat_width / 2
    p = [
        rng.uniform(
            [-hd - 0.3, -hw - 0.3, -0.2], [hd + 0.3, hw + 0.3, chair.seat_height + chair.back_height + 0.2], (n, 3)
        )
    ]
    for box, o in shape.parts:
        p.append(_box_points(box.half, 800) + o)
    z = rng.uniform(-0.1, chair.seat_height, 400)
    x = rng.uniform(-hd - 0.2, hd + 0.2, 400)
    y = rng.uniform(-hw - 0.2, hw + 0.2, 400)
    p.append(np.c_[x, np.zeros(400), z])  # mirror plane y = 0: legs 0/1 and 2/3 tie
    p.append(np.c_[np.zeros(400), y, z])  # mirror plane x = 0: legs 0/2 and 1/3 tie
    return np.concatenate(p)


def _compare(shape, p: np.ndarray) -> None:
    """The kernel at the identity pose (p reaches it exactly) equals the numpy field to 1e-12."""
    phi, g, c = shape.world(p, *IDENTITY)
    rphi, rg, rc = shape.local(*p.T, np)
    np.testing.assert_allclose(phi, rphi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g, np.stack(rg, 1), rtol=0, atol=1e-12)
    np.testing.assert_allclose(c, np.stack(rc, 1), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("prim", BOXES, ids=lambda p: f"box{p.size}{p.scale}")
def test_box_kernel_matches_numpy_inside_on_faces_edges_corners(prim):
    shape = primitive_shape(prim)
    p = _box_points(shape.half)
    _compare(shape, p)
    on = np.abs(shape.local(*p.T, np)[0]) == 0
    assert on.sum() > len(p) // 5  # corners, and parts of the face planes and edge lines, are really on the surface


def test_box_kernel_keeps_the_face_order_on_ties():
    """Inside a cube on the diagonal, x's face wins over y's over z's (numpy's rule), sign +1 at 0."""
    shape = primitive_shape(BOXES[2])
    p = np.array([[0.1, 0.1, 0.1], [-0.05, 0.1, 0.15], [0.0, 0.0, 0.0], [0.0, -0.1, -0.1]])
    phi, g, c = shape.world(p, *IDENTITY)
    np.testing.assert_array_equal(g, [[1, 0, 0], [0, 0, 1], [1, 0, 0], [0, -1, 0]])
    np.testing.assert_allclose(phi, [0.1, 0.05, 0.2, 0.1], rtol=0, atol=1e-15)
    _compare(shape, p)


def test_chair_kernel_matches_numpy_with_the_first_part_on_ties():
    chair = Chair()
    shape = chair_shape(chair)
    p = _chair_points(chair)
    _compare(shape, p)
    phis = np.stack([box_phi(*(p - o).T, *box.half, np) for box, o in shape.parts])
    tie = (phis == phis.min(0)).sum(0) > 1
    assert tie.sum() > 500  # exactly equidistant parts are really exercised
    _, _, c = shape.world(p[tie], *IDENTITY)
    first = np.argmax(phis[:, tie] == phis[:, tie].min(0), axis=0)
    own = np.stack([box_phi(*(c - shape.parts[k][1]).T, *shape.parts[k][0].half, np) for k in range(len(shape.parts))])
    np.testing.assert_allclose(
        own[first, np.arange(len(first))], 0.0, atol=1e-12
    )  # the closest point lies on the first part


@pytest.mark.parametrize("geom", [*BOXES, Chair()], ids=lambda g: getattr(g, "kind", "chair"))
def test_pose_per_frame_fused_kernel_equals_the_numpy_pose_transform(geom):
    """Links over frames and one pose run in the kernel; per-point poses (N, 7) transform in numpy."""
    field = ObjectField.from_geometry(geom)
    rng = np.random.default_rng(13)
    frames, links = 60, 20
    local = rng.uniform(-0.8, 0.8, (frames, links, 3)) + [0.0, 0.0, 0.4 * isinstance(geom, Chair)]
    poses = np.c_[rng.uniform(-2, 2, (frames, 3)), rng.normal(size=(frames, 4)) * rng.uniform(0.2, 3.0, (frames, 1))]
    world = check_pose_per_frame(field, local, poses)
    one = field.query(world[0], poses[0])
    for a, b in zip(one, field.query(world[0], np.tile(poses[0], (links, 1)))):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
