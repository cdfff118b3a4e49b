"""ObjectField / ObjectFields: poses, link batches, the chair union, nearest object, numpy == torch, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from pipeline.distance.field import ObjectField, ObjectFields
from pipeline.errors import InputError
from pipeline.geometry import Chair, Primitive, geometry_to_dict

RNG = np.random.default_rng(11)
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
GEOMS = [
    Primitive("box", (0.3, 0.2, 0.1), (1.0, 2.0, 0.5)),
    Primitive("sphere", (0.2,), (1.0, 1.5, 0.5)),
    Primitive("cylinder", (0.1, 0.3)),
    Primitive("capsule", (0.1, 0.2), (2.0, 1.5, 0.6)),
    Chair(),
]


def _pose(seed: int) -> np.ndarray:
    return np.r_[RNG.normal(size=3), Rotation.random(random_state=seed).as_quat(scalar_first=True)]


@pytest.mark.parametrize("geom", GEOMS, ids=lambda g: type(g).__name__ + getattr(g, "kind", ""))
def test_pose_moves_queries_into_the_object_frame_and_grads_back(geom):
    field = ObjectField.from_geometry(geom)
    pose = _pose(1)
    R = Rotation.from_quat(pose[3:], scalar_first=True).as_matrix()
    local = RNG.normal(size=(400, 3)) * 0.4
    world = local @ R.T + pose[:3]
    a, b = field.query(world, pose), field.query(local, IDENTITY)
    np.testing.assert_allclose(a.phi, b.phi, atol=1e-12)
    np.testing.assert_allclose(a.grad, b.grad @ R.T, atol=1e-9)
    np.testing.assert_allclose(a.closest, b.closest @ R.T + pose[:3], atol=1e-12)
    # the same query with a per-point pose and as (frames x links)
    c = field.query(world, np.tile(pose, (len(world), 1)))
    np.testing.assert_allclose(c.phi, a.phi, atol=1e-12)
    links = field.query_links(world.reshape(20, 20, 3), np.tile(pose, (20, 1)))
    assert links.phi.shape == (20, 20) and links.grad.shape == (20, 20, 3)
    np.testing.assert_allclose(links.grad.reshape(-1, 3), a.grad, atol=1e-12)


def test_unnormalised_quaternion_is_normalised():
    field = ObjectField.from_geometry(GEOMS[0])
    pose = _pose(2)
    p = RNG.normal(size=(50, 3))
    scaled = pose.copy()
    scaled[3:] *= 3.0
    np.testing.assert_allclose(field.query(p, scaled).phi, field.query(p, pose).phi, atol=1e-12)


def test_chair_is_the_union_of_its_parts_nearest_part():
    chair = Chair()
    field = ObjectField.from_geometry(chair)
    parts = [(ObjectField.from_geometry(prim), c) for _, prim, c in chair.parts()]
    p = RNG.uniform([-0.5, -0.5, -0.1], [0.5, 0.5, 1.0], (2000, 3))
    each = [f.query(p, np.r_[c, 1.0, 0, 0, 0]) for f, c in parts]
    near = np.argmin(np.stack([s.phi for s in each]), axis=0)
    s = field.query(p, IDENTITY)
    np.testing.assert_allclose(s.phi, np.min([e.phi for e in each], axis=0), atol=1e-12)
    np.testing.assert_allclose(s.closest, np.stack([each[k].closest[i] for i, k in enumerate(near)]), atol=1e-12)
    above_seat = field.query(np.array([[0.0, 0.0, chair.seat_height + 0.1]]), IDENTITY)
    assert above_seat.phi[0] == pytest.approx(0.1) and np.allclose(above_seat.grad[0], [0, 0, 1])


def test_several_objects_report_the_nearest_and_its_index():
    fields = ObjectFields(tuple(ObjectField.from_geometry(Primitive("sphere", (0.1,))) for _ in range(3)))
    poses = np.array([[0.0, 0, 0, 1, 0, 0, 0], [1.0, 0, 0, 1, 0, 0, 0], [2.0, 0, 0, 1, 0, 0, 0]])
    p = np.array([[-0.5, 0, 0], [0.9, 0, 0.2], [1.6, 0, 0], [5.0, 0, 0]])
    s = fields.query(p, poses)
    assert s.object_index.tolist() == [0, 1, 2, 2]
    np.testing.assert_allclose(s.phi, [0.4, np.hypot(0.1, 0.2) - 0.1, 0.3, 2.9], atol=1e-12)
    links = fields.query_links(p.reshape(2, 2, 3), np.stack([poses, poses]))
    assert links.object_index.tolist() == [[0, 1], [2, 2]]
    with pytest.raises(InputError, match="object poses: expected 3 poses"):
        fields.query(p, poses[:2])


@pytest.mark.parametrize("geom", GEOMS, ids=lambda g: type(g).__name__ + getattr(g, "kind", ""))
def test_numpy_and_torch_agree(geom):
    field = ObjectField.from_geometry(geom)
    p = RNG.normal(size=(3000, 3)) * 0.4
    poses = np.stack([_pose(s) for s in range(10)])
    a = field.query_links(p.reshape(10, 300, 3), poses)
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    for dev in devices:
        b = field.query_links(torch.as_tensor(p.reshape(10, 300, 3), device=dev), torch.as_tensor(poses, device=dev))
        for x, y in zip(a, b):
            assert isinstance(y, torch.Tensor) and y.device.type == dev
            np.testing.assert_allclose(y.cpu().numpy(), x, atol=1e-5)


def test_object_scale_invariance_of_the_approach_to_a_box():
    """The same hand approach (along the face normal, same distances to the surface) toward a box
    at 0.4x, 1.0x and 1.6x gives the same phi and grad traces near contact."""
    gaps = np.linspace(0.15, -0.02, 60)  # hand-to-surface distance, last few frames inside
    traces = []
    for s in (0.4, 1.0, 1.6):
        box = Primitive("box", (0.2, 0.15, 0.1)).scaled(s)
        hand = np.stack([0.2 * s + gaps, 0.02 * s + 0 * gaps, 0.01 * s + 0 * gaps], 1)
        pose = _pose(3)
        R = Rotation.from_quat(pose[3:], scalar_first=True).as_matrix()
        t = ObjectField.from_geometry(box).query_links((hand @ R.T + pose[:3])[:, None], np.tile(pose, (len(gaps), 1)))
        traces.append((t.phi[:, 0], t.grad[:, 0] @ R))
    for phi, grad in traces:
        np.testing.assert_allclose(phi, np.abs(gaps), atol=1e-12)
        np.testing.assert_allclose(grad, np.tile([1.0, 0, 0], (len(gaps), 1)), atol=1e-12)


@pytest.mark.parametrize(
    "points, pose, match",
    [
        (np.zeros((4, 2)), IDENTITY, r"box points: expected shape \(N, 3\), got \(4, 2\)"),
        (np.zeros(3), IDENTITY, r"box points: expected shape \(N, 3\), got \(3,\)"),
        (np.zeros((4, 3)), IDENTITY[:6], r"box pose: expected shape \(7\), got \(6,\)"),
        (np.zeros((4, 3)), np.zeros((3, 7)), r"box pose: expected shape \(4, 7\), got \(3, 7\)"),
        (np.array([[0, 0, 0], [np.nan, 0, 0]]), IDENTITY, "box points: non-finite value at row 1"),
        (np.zeros((4, 3)), np.zeros(7), r"box pose: quaternion \(qw, qx, qy, qz\) is zero"),
    ],
)
def test_bad_input_is_a_one_line_error_naming_the_object(points, pose, match):
    field = ObjectField.from_geometry(GEOMS[0], name="box")
    with pytest.raises(InputError, match=match) as info:
        field.query(points, pose)
    assert "\n" not in str(info.value)


def test_bad_link_batch_shapes_are_rejected():
    field = ObjectField.from_geometry(GEOMS[0], name="box")
    with pytest.raises(InputError, match=r"box poses: expected shape \(5, 7\), got \(4, 7\)"):
        field.query_links(np.zeros((5, 2, 3)), np.tile(IDENTITY, (4, 1)))
    with pytest.raises(InputError, match=r"box link points: expected shape \(N, N, 3\)"):
        field.query_links(np.zeros((5, 3)), np.tile(IDENTITY, (5, 1)))


def test_zero_scale_is_rejected_naming_the_object():
    with pytest.raises(ValueError, match="scale must be three positive finite numbers"):
        Primitive("box", (0.1, 0.1, 0.1), (1.0, 0.0, 1.0))
    d = geometry_to_dict(Primitive("box", (0.1, 0.1, 0.1)))
    d["scale"] = [1.0, 0.0, 1.0]
    with pytest.raises(InputError, match=r"^<memory>: crate geometry: scale must be three positive"):
        ObjectField.from_geometry(d, name="crate")


def test_boxes_of_their_own_sizes_in_one_batch_match_one_field_each():
    """boxes_query_links (the environments' batch of differently scaled boxes) gives each box's own ObjectField
    answer, in numpy and in torch, points inside the boxes included."""
    from pipeline.distance.field import boxes_query_links

    halves = RNG.uniform(0.05, 0.4, (5, 3))
    poses = np.stack([_pose(s) for s in range(5)])
    points = poses[:, None, :3] + RNG.normal(scale=0.3, size=(5, 14, 3))
    phi, grad = boxes_query_links(points, poses, halves)
    for n in range(5):
        want = ObjectField.from_geometry(Primitive("box", tuple(halves[n]))).query(points[n], poses[n])
        np.testing.assert_allclose(phi[n], want.phi, atol=1e-12)
        np.testing.assert_allclose(grad[n], want.grad, atol=1e-12)
    assert (phi > 0).any() and (np.abs(phi) < halves.max()).any()
    t_phi, t_grad = boxes_query_links(*(torch.as_tensor(a) for a in (points, poses, halves)))
    np.testing.assert_allclose(t_phi.numpy(), phi, atol=1e-12)
    np.testing.assert_allclose(t_grad.numpy(), grad, atol=1e-12)


def test_chairs_of_their_own_sizes_in_one_batch_match_one_field_each():
    """boxes_query_links with parts (half-extents and centres per chair) gives each chair's own ObjectField answer,
    the nearest part's field, in numpy and in torch."""
    from pipeline.distance.field import boxes_query_links

    chairs = [Chair().scaled(s) for s in RNG.uniform(0.4, 1.6, (4, 3))]
    half = np.array([[p.half_extents for _, p, _ in c.parts()] for c in chairs])
    centre = np.array([[o for _, _, o in c.parts()] for c in chairs])
    poses = np.stack([_pose(s) for s in range(4)])
    points = poses[:, None, :3] + RNG.normal(scale=0.4, size=(4, 14, 3))
    phi, grad = boxes_query_links(points, poses, half, centre)
    for n, chair in enumerate(chairs):
        want = ObjectField.from_geometry(chair).query(points[n], poses[n])
        np.testing.assert_allclose(phi[n], want.phi, atol=1e-12)
        np.testing.assert_allclose(grad[n], want.grad, atol=1e-12)
    t_phi, t_grad = boxes_query_links(*(torch.as_tensor(a) for a in (points, poses, half, centre)))
    np.testing.assert_allclose(t_phi.numpy(), phi, atol=1e-12)
    np.testing.assert_allclose(t_grad.numpy(), grad, atol=1e-12)
