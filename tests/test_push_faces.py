"""Pushing hands moved onto the faces that can give the push (physicalize.push_faces), on a real MuJoCo box geom
and, where ../shared is present, on a real InterAct box slide."""

from pathlib import Path

import mujoco
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from physicalize.push_faces import PushFaces, _corner, body_vertices, object_hull, push_direction, push_face, pushed
from pipeline.rotations import quat_mat

HALF = np.array([0.2, 0.15, 0.18])
MU = 0.35  # the planner's mu / safety at the scenes' hand friction 0.7


def _box_hull(euler=(0.0, 0.0, 0.0)):
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="box")
    body.add_freejoint()
    q = np.zeros(4)
    mujoco.mju_euler2Quat(q, np.asarray(euler, float), "xyz")
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=HALF, quat=q)
    m = spec.compile()
    return m, object_hull(m, [0])


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def test_box_geom_has_its_four_side_faces_for_an_upright_frame():
    m, hull = _box_hull()
    assert len(body_vertices(m, [0])) == 8
    faces = hull.side_faces(np.array([0.0, 0, 1]))
    normals = sorted(tuple(np.round(f.n, 6)) for f in faces)
    assert normals == sorted([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)])
    for f in faces:
        assert f.offset == pytest.approx(float(np.abs(f.n) @ HALF))
        assert f.height == pytest.approx((-HALF[2], HALF[2]))


def test_side_faces_follow_the_world_vertical_in_a_turned_frame():
    """A scanned object's body frame is not z-up (InterAct's large box is upside down, its plastic box y-up): with
    ``up`` = the body's y axis the side faces are its +-x and +-z faces."""
    _, hull = _box_hull()
    up = np.array([0.0, 1, 0])
    normals = sorted(tuple(np.round(f.n, 6)) for f in hull.side_faces(up))
    assert normals == sorted([(1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1)])
    assert all(abs(f.n @ up) < 1e-9 for f in hull.side_faces(up))


def test_two_hands_on_one_face_at_55_degrees_take_the_corner():
    """Both hands on the -y face (inward +y) pushing along u at 55 deg from it: out of the reduced cone (19 deg), so
    the right hand keeps that face (its inward normal is counter-clockwise of u: on a pusher's right) and the left
    hand goes to the adjacent -x face; together their normals bracket u."""
    _, hull = _box_hull()
    up = np.array([0.0, 0, 1])
    u = np.array([np.sin(np.radians(55)), np.cos(np.radians(55)), 0.0])  # 55 deg from +y towards +x
    n_in = np.array([0.0, 1, 0])
    left = np.array([-0.12, -HALF[1] - 0.03, 0.1])
    right = np.array([0.05, -HALF[1] - 0.03, 0.1])
    moved = [push_face(hull, up, c, n_in, u, hand, True, MU) for hand, c in ((0, left), (1, right))]
    assert np.cross(u, n_in) @ up > 0 and moved[1] is None
    point, normal = moved[0]
    assert normal == pytest.approx([1.0, 0, 0])  # inward +x: the -x face, 35 deg from u
    assert point[0] == pytest.approx(-HALF[0] - 0.03)  # the old stand-off from the new face
    assert point[2] == pytest.approx(0.1)
    assert abs(point[1]) <= HALF[1] - 0.06 + 1e-9  # inside the face's edges
    # u lies between the two normals: pressing alone can give it
    assert (np.cross(normal, u) @ up) * (np.cross(u, n_in) @ up) > 0


def test_a_hand_that_can_push_or_would_reach_across_stays():
    _, hull = _box_hull()
    up = np.array([0.0, 0, 1])
    c = np.array([-HALF[0] - 0.02, 0.0, 0.05])
    n_in = np.array([1.0, 0, 0])
    assert push_face(hull, up, c, n_in, _unit([1, 0.2, 0]), 1, True, MU) is None  # 11 deg: within its cone
    # the object moves towards the hand: the face that could push it is on the far side
    assert push_face(hull, up, c, n_in, np.array([-1.0, 0, 0]), 0, False, MU) is None
    assert push_face(hull, up, c, n_in, np.zeros(3), 0, False, MU) is None


def test_hands_stay_where_no_face_nor_corner_can_push():
    """A pair whose two nearest faces do not both push the motion forward (a table dragged towards the body across its
    faces: sub2_largetable_004) keeps the human's placement."""
    up = np.array([0.0, 0, 1])
    across = np.array([[0.0, 1, 0], [0.0, -1, 0]])
    assert _corner(across, _unit([0.96, 0.29, 0]), up) is None
    left, right = _corner(np.array([[1.0, 0, 0], [0.0, 1, 0], [-1.0, 0, 0]]), _unit([1, 0.9, 0]), up)
    assert (left, right) == (0, 1)  # +x is clockwise of the motion: the left hand's face


def test_a_hand_on_the_lid_moves_onto_a_side_face():
    _, hull = _box_hull()
    up = np.array([0.0, 0, 1])
    c = np.array([0.0, 0.0, HALF[2] + 0.03])
    point, normal = push_face(hull, up, c, np.array([0.0, 0, -1]), np.array([1.0, 0, 0]), 0, False, MU)
    assert normal == pytest.approx([1.0, 0, 0])
    assert point[0] == pytest.approx(-HALF[0] - 0.03)
    assert point[2] == pytest.approx(HALF[2] - 0.06)  # clamped inside the face's top edge
    assert point[1] == pytest.approx(0.0)  # alone, it pushes on the vertical through the centre of mass


def test_push_direction_is_the_motion_in_the_objects_frame():
    T, fps = 30, 30.0
    q = np.zeros(4)
    mujoco.mju_euler2Quat(q, np.array([np.pi, 0, 0.5]), "xyz")  # upside down and turned
    pose = np.tile(np.r_[0.0, 0, 0.2, q], (T, 1))
    pose[:, 0] = np.linspace(0, 0.5, T)
    u = push_direction(pose, fps)
    assert quat_mat(q) @ u == pytest.approx([1.0, 0, 0], abs=1e-9)
    assert pushed(pose, 0.1, 0.02) and not pushed(pose[:5], 0.1, 0.02)


def _lone_push(angle_deg: float, other_dist: float):
    """Hand 0 alone pushes the upright box 0.6 m at ``angle_deg`` from its +x face normal; hand 1 free at
    ``other_dist`` from it. Returns the planner (after recruiting) and the labels it returns."""
    _, hull = _box_hull()
    T, fps = 40, 30.0
    pose = np.tile(np.r_[0.0, 0, HALF[2], 1, 0, 0, 0], (T, 1))
    a = np.radians(angle_deg)
    pose[:, :2] = np.linspace(0, 0.6, T)[:, None] * [np.cos(a), np.sin(a)]
    key = np.full((T, 2), -1)
    key[:, 0] = 0
    faces = PushFaces({0: hull}, key, np.zeros(T, bool), {0: pose}, fps, MU, 0.1, 0.02)
    labels = np.zeros((T, 2), bool)
    labels[:, 0] = True
    dist = np.full((T, 2), np.inf)
    dist[:, 0], dist[:, 1] = 0.0, other_dist
    return faces, faces.recruit(dist, 0.1, labels)


def test_a_free_hand_near_a_lone_diagonal_push_joins_it():
    faces, labels = _lone_push(45.0, 0.06)
    assert (faces.key[:, 1] == 0).all() and labels[:, 1].all()
    # recruited, it has no face of its own: it is placed on the corner's other face at the default stand-off
    up, u = np.array([0.0, 0, 1]), push_direction(faces.poses[0], faces.fps)
    point, normal = push_face(faces.hulls[0], up, np.array([-0.3, 0.3, 0.05]), np.zeros(3), u, 1, True, MU)
    assert normal @ u == pytest.approx(np.cos(np.radians(45)))


@pytest.mark.parametrize("angle, dist", [(10.0, 0.06), (45.0, 0.3)])
def test_no_hand_joins_a_push_one_face_can_give_or_from_afar(angle, dist):
    faces, labels = _lone_push(angle, dist)
    assert (faces.key[:, 1] == -1).all() and not labels[:, 1].any()


@needs_shared
def test_a_real_lid_hand_is_moved_onto_a_side_face():
    """sub8_largebox_001: the human pushes the box 1.5 m with the left hand on its lid (the plan pressed it down
    29 N for 10 N along). Planned now, the left hand is on a side face: its normal horizontal, and the holding
    hands' normals bracket the box's motion."""
    from physicalize.grasp import grasp_schedule
    from physicalize.problem import scene_for
    from physicalize.reference import build_reference
    from physicalize.start import clean_start
    from pipeline.readers import read_clips
    from retarget.clip import retarget_clip

    clip = clean_start(retarget_clip(read_clips(Path(SHARED_MOCAP / "interact" / "sub8_largebox_001.pt"))[0])[0])
    scene = scene_for(clip, "mjlab")
    ref = build_reference(scene.model, clip.qpos, clip.fps)
    pose = clip.objects[0].pose
    g = grasp_schedule(scene, ref, clip.contact_links, clip.contacts, {o.name: o.pose for o in clip.objects})
    both = np.flatnonzero(g.grasped.all(axis=1))
    assert len(both) > 60
    t = int(both[len(both) // 2])
    n = g.normal[t]
    assert np.abs(n[:, 2]).max() < 0.3  # no hand on the lid
    u = np.r_[pose[both[-1], :2] - pose[both[0], :2], 0.0]
    u /= np.linalg.norm(u)
    assert (np.cross(n[0], u)[2]) * (np.cross(u, n[1])[2]) > 0  # the normals bracket the motion
