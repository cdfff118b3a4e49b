"""The depth camera (train.vision.camera) on a real G1 scene: a wall facing the camera at a known distance reads it
to the millimetre at the centre and in the corner (z-depth, not ray length), the camera follows the torso, a pose
offset moves and turns it (none or a zero one: the nominal pose bit for bit), and bad settings are one-line errors."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.robot import actuator_profile
from pipeline.scene import SceneObject, build_scene
from train.vision.camera import CameraOffset, DepthCamera

CAMERA = DepthCamera(width=33, height=21, geom_groups=(0,))  # odd sizes: a pixel on the axis; the robot unseen


def _scene(wall_pose=(0.0, 0.0, -5.0, 1.0, 0.0, 0.0, 0.0)):
    wall = SceneObject("wall", Primitive("box", (0.005, 3.0, 3.0)), pose=wall_pose, fixed=True)
    scene = build_scene([wall], actuator_profile("mjlab"))
    d = mujoco.MjData(scene.model)
    d.qpos[2] += 3.0  # the robot high above the floor: the wall alone in view
    mujoco.mj_forward(scene.model, d)
    return scene.model, d


def test_a_wall_facing_the_camera_reads_its_distance_at_the_centre_and_the_corner():
    m, d = _scene()
    origin, C = CAMERA.frame(m, d)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, C.reshape(-1))
    distance = 1.0
    centre = origin + (distance + 0.005) * C[:, 0]  # the wall's near face at 1 m along the optical axis
    m, d = _scene((*centre, *q))
    depth = CAMERA.render(m, d)
    assert depth.shape == (21, 33) and depth.dtype == np.float32
    assert abs(depth[10, 16] - distance) < 1e-3  # the centre pixel's ray is the optical axis
    assert abs(depth[0, 0] - distance) < 1e-3 and abs(depth[-1, -1] - distance) < 1e-3  # z-depth, not range
    far = CAMERA.render(*_scene())  # nothing in view: the far plane
    assert np.all(far == CAMERA.far)


def test_the_camera_follows_the_torso():
    m, d = _scene()
    origin, C = CAMERA.frame(m, d)
    root = d.qpos[:3].copy()
    d.qpos[3:7] = [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]  # the robot turned 90 degrees left
    mujoco.mj_forward(m, d)
    turned_origin, turned = CAMERA.frame(m, d)
    yaw = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(turned, yaw @ C, atol=1e-9)
    np.testing.assert_allclose(turned_origin - root, yaw @ (origin - root), atol=1e-9)
    assert C[2, 0] < -0.6  # pitched down ~48 degrees: the optical axis points at the floor ahead
    seen = DepthCamera().render(m, d)  # the default groups see the robot's own collision primitives
    assert seen.shape == (40, 64) and seen.min() < DepthCamera().far


@pytest.mark.parametrize(
    "change, field",
    [
        ({"fov_x_deg": 180.0}, "fov_x_deg"),
        ({"fov_y_deg": 0.0}, "fov_y_deg"),
        ({"width": 4}, "width"),
        ({"height": 300}, "height"),
        ({"near": 3.0, "far": 1.0}, "near"),
        ({"geom_groups": (0, 9)}, "geom_groups"),
    ],
)
def test_bad_settings_are_one_line_errors(change, field):
    with pytest.raises(InputError) as e:
        replace(DepthCamera(), **change)
    assert e.value.field == field and "\n" not in str(e.value)


def test_a_camera_on_a_body_the_g1_lacks():
    m, d = _scene()
    with pytest.raises(InputError, match="body: 'd435_link' is not a body"):
        DepthCamera(body="d435_link").render(m, d)


def _wall_at(distance: float):
    """The scene with a wall facing the nominal camera, its near face ``distance`` m along the optical axis."""
    m, d = _scene()
    origin, C = CAMERA.frame(m, d)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, C.reshape(-1))
    return _scene((*(origin + (distance + 0.005) * C[:, 0]), *q))


def test_a_zero_offset_is_the_nominal_pose_bit_for_bit():
    m, d = _wall_at(1.0)
    for offset in (None, CameraOffset(), CameraOffset((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))):
        origin, C = CAMERA.frame(m, d, offset)
        assert np.array_equal(origin, CAMERA.frame(m, d)[0]) and np.array_equal(C, CAMERA.frame(m, d)[1])
        assert np.array_equal(CAMERA.render(m, d, offset), CAMERA.render(m, d))


def test_an_offset_moves_and_turns_the_camera():
    m, d = _wall_at(1.0)
    origin, C = CAMERA.frame(m, d)
    p = CAMERA.pitch
    forward = 0.2 * np.array([np.cos(p), 0.0, -np.sin(p)])  # the optical axis in the torso's frame
    closer = CAMERA.render(m, d, CameraOffset(pos=tuple(forward)))
    assert abs(closer[10, 16] - 0.8) < 1e-3 and abs(closer[0, 0] - 0.8) < 1e-3  # 0.2 m nearer the wall
    tipped = CAMERA.frame(m, d, CameraOffset(rot=(0.0, 0.1, 0.0)))  # pitch: as the mount's, further down
    for a, b in zip(tipped, replace(CAMERA, pitch=p + 0.1).frame(m, d)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    a = 0.1
    _, yawed = CAMERA.frame(m, d, CameraOffset(rot=(0.0, 0.0, a)))
    np.testing.assert_allclose(yawed, C @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]))
    _, rolled = CAMERA.frame(m, d, CameraOffset(rot=(a, 0.0, 0.0)))  # roll: about the optical axis
    np.testing.assert_allclose(rolled[:, 0], C[:, 0], atol=1e-12)
    assert abs(CAMERA.render(m, d, CameraOffset(rot=(a, 0.0, 0.0)))[10, 16] - 1.0) < 1e-3


def test_an_offset_turns_about_x_then_y_then_z_of_the_camera():
    m, d = _scene()
    _, C = CAMERA.frame(m, d)
    (cx, cy, cz), (sx, sy, sz) = np.cos([0.3, -0.2, 0.5]), np.sin([0.3, -0.2, 0.5])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    np.testing.assert_allclose(CAMERA.frame(m, d, CameraOffset(rot=(0.3, -0.2, 0.5)))[1], C @ rx @ ry @ rz, atol=1e-12)


def test_offsets_add():
    s = CameraOffset((0.01, 0.0, -0.02), (0.001, 0.002, 0.0)) + CameraOffset((0.01, 0.03, 0.0), (0.0, 0.001, 0.01))
    np.testing.assert_allclose(s.pos, (0.02, 0.03, -0.02))
    np.testing.assert_allclose(s.rot, (0.001, 0.003, 0.01))
    assert CameraOffset().is_zero and not s.is_zero


@pytest.mark.parametrize("change", [{"pos": (0.0, 0.0)}, {"rot": (0.0, float("nan"), 0.0)}])
def test_a_bad_offset_is_a_one_line_error(change):
    with pytest.raises(InputError) as e:
        CameraOffset(**change)
    assert e.value.field == f"offset.{next(iter(change))}" and "\n" not in str(e.value)
