"""Seat support (physicalize.seat): the reference's seat points, the plan's support polygon with them, and the
QP's seat contact points, on the G1 standing over a post under its pelvis."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physicalize.plan import SEAT_LEAD_S, support_polygon, zmp_reference
from physicalize.reference import build_reference, place_on_floor
from physicalize.seat import SEAT_LINKS, SeatConfig, seat_support, support_points
from physicalize.wbc import WholeBodyController
from pipeline.geometry import Primitive
from pipeline.robot import default_qpos
from pipeline.scene import SceneObject, build_scene

HALF = (0.03, 0.03)  # a post between the legs, under the pelvis
T = 100
LINKS = ("pelvis", "left_wrist_yaw_link")


def _post_scene(gap: float):
    """The standing robot and a fixed post whose top is ``gap`` below the pelvis' collision geom; its qpos."""
    probe = build_scene(
        [SceneObject("post", Primitive("box", (*HALF, 0.05)), pose=(0, 0, 0.05, 1, 0, 0, 0), fixed=True)]
    )
    q0 = place_on_floor(probe.model, default_qpos(probe.profile)[None])[0]
    m, d = probe.model, mujoco.MjData(probe.model)
    d.qpos[:36] = q0
    mujoco.mj_forward(m, d)
    pelvis = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body("pelvis").id and m.geom_contype[g]]
    post = m.geom("post_col0").id
    above = min(
        mujoco.mj_geomDistance(m, d, g, post, 2.0, None) for g in pelvis
    )  # pelvis bottom above the 0.1 m high post
    top = 0.1 + above - gap
    x = float(d.xpos[m.body("pelvis").id][0])
    scene = build_scene(
        [SceneObject("post", Primitive("box", (*HALF, top / 2)), pose=(x, 0, top / 2, 1, 0, 0, 0), fixed=True)]
    )
    return scene, q0


@pytest.fixture(scope="module")
def near():
    return _post_scene(0.01)


def _labels(a: int, b: int) -> np.ndarray:
    out = np.zeros((T, len(LINKS)), bool)
    out[a:b, 0] = True
    return out


def test_seat_points_on_the_labelled_frames_widened(near):
    """A post 1 cm under the pelvis: the pelvis row is a seat point on the labelled frames widened by ``dilate``,
    the other sitting links (hips, beside the post) have none, and the point lies on the post's top."""
    scene, q0 = near
    ref = build_reference(scene.model, np.tile(q0, (T, 1)), 50.0)
    pts = seat_support(scene.model, ref, LINKS, _labels(40, 60), None, SeatConfig(dilate=10))
    on = np.isfinite(pts[:, :, 0])
    assert on[30:70, SEAT_LINKS.index("pelvis")].all() and not on[:30].any() and not on[70:].any()
    assert not np.delete(on, SEAT_LINKS.index("pelvis"), axis=1).any()
    assert (
        0.3 < pts[50, 0, 2] < q0[2] and np.hypot(*(pts[50, 0, :2] - q0[:2])) < 0.1
    )  # under the pelvis, well above the floor
    assert seat_support(scene.model, ref, LINKS, _labels(0, 0), None) is None  # never labelled
    assert (
        seat_support(scene.model, ref, ("left_wrist_yaw_link",), _labels(40, 60)[:, 1:], None) is None
    )  # no pelvis label column


def test_no_seat_point_out_of_reach():
    """The post 5 cm under the pelvis (reach 2 cm): labelled frames get no seat point, so the clip never sits."""
    scene, q0 = _post_scene(0.05)
    ref = build_reference(scene.model, np.tile(q0, (T, 1)), 50.0)
    assert seat_support(scene.model, ref, LINKS, _labels(40, 60), None) is None


def test_support_polygon_takes_in_the_seat_points(near):
    """The support polygon with the seat points reaches behind the heels to the post; without them it is the feet's."""
    scene, q0 = near
    ref = build_reference(scene.model, np.tile(q0, (T, 1)), 50.0)
    ref.seat = np.full((T, len(SEAT_LINKS), 3), np.nan)
    ref.seat[50, 0] = ref.corners[50, :, :, :].reshape(-1, 3).mean(0) + [-0.3, 0, 0.4]  # 30 cm behind the feet's centre
    feet = support_polygon(ref, 50, seat=False)
    both = support_polygon(ref, 50)
    assert both[:, 0].min() == pytest.approx(ref.seat[50, 0, 0])
    assert feet[:, 0].min() > ref.seat[50, 0, 0] + 0.1
    assert np.allclose(np.sort(support_polygon(ref, 49)[:, 0]), np.sort(feet[:, 0]))


def test_the_plan_stands_on_the_feet_before_the_seat_lets_go(near):
    """Seated on frames 40-79 with the CoM 20 cm behind the feet: the ZMP reference follows it onto the seat,
    except over the last SEAT_LEAD_S of the run, where it is back in the feet's polygon."""
    scene, q0 = near
    ref = build_reference(scene.model, np.tile(q0, (T, 1)), 50.0)
    feet = support_polygon(ref, 50, seat=False)
    ref.seat = np.full((T, len(SEAT_LINKS), 3), np.nan)
    ref.seat[40:80, 0] = ref.corners[50].reshape(-1, 3).mean(0) + [-0.3, 0, 0.4]
    ref.com[40:80, 0] -= 0.2
    zmp = zmp_reference(ref)
    lead = int(round(SEAT_LEAD_S * ref.fps))
    assert lead > 0
    np.testing.assert_allclose(zmp[40 : 80 - lead], ref.com[40 : 80 - lead, :2])  # on the seat: the CoM's projection
    assert (zmp[80 - lead : 80, 0] >= feet[:, 0].min() - 1e-9).all()  # the last frames: over the feet


def test_support_points_take_the_post_under_the_pelvis():
    """The pelvis sunk 3 mm into the post: one QP seat point on the pelvis, normal up into the robot, and the
    measured contact's generalized force lifts the root (tau_z > 0); the feet's floor contacts are not seat points."""
    scene, q0 = _post_scene(-0.003)
    m = scene.model
    ctrl = WholeBodyController(m, scene.profile)
    d = mujoco.MjData(m)
    d.qpos[:36] = q0
    mujoco.mj_forward(m, d)
    pts = support_points(ctrl.contacts, d, ctrl.unseated_geoms)
    assert [m.body(p.body).name for p in pts] == ["pelvis"]
    p = pts[0]
    assert p.frame[0] @ [0, 0, 1.0] > 0.99 and np.allclose(p.frame @ p.frame.T, np.eye(3), atol=1e-9)
    assert p.tau[2] > 0.0
